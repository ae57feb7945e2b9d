"""LeRobot's policies behind gymnast's Policy contract: exact log-probabilities of what they
sample, and features they cannot be given refused by name (the way back to LeRobot after RL is
tests/rl/test_lerobot_rl.py's)."""

import pytest
import torch

from gymnast.policy.load import load_policy

INSTRUCTIONS = ["reach the goal", "push the puck", "open the drawer"]


@pytest.fixture(params=["act", "smolvla"])
def folder(request, lerobot_act, lerobot_smolvla):
    return {"act": lerobot_act, "smolvla": lerobot_smolvla}[request.param]


def _images(seed: int = 0) -> torch.Tensor:
    return torch.randint(0, 256, (len(INSTRUCTIONS), 96, 96, 3), dtype=torch.uint8,
                         generator=torch.Generator().manual_seed(seed))


def test_log_prob_recomputes_the_sampled_chunks_density_and_its_gradient_reaches_the_policy(folder):
    policy = load_policy(f"lerobot:{folder}")
    kind = {"act": "LeRobotGaussianPolicy", "smolvla": "LeRobotFlowPolicy"}[policy.config.type]
    assert type(policy).__name__ == kind and (policy.chunk_size, policy.action_dim) == (5, 4)
    sample = policy.sample(_images(), INSTRUCTIONS, 1.3, torch.Generator().manual_seed(0))
    assert sample.actions.shape == (3, 5, 4) and sample.logp.shape == (3, 20)
    logp = policy.log_prob(_images(), INSTRUCTIONS, sample.tokens, 1.3)
    torch.testing.assert_close(logp, sample.logp, atol=1e-4, rtol=0)
    logp.sum().backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in policy.policy.parameters())
    # Another temperature is another distribution: the same chunk gets another density.
    assert not torch.allclose(policy.log_prob(_images(), INSTRUCTIONS, sample.tokens, 0.7), logp)


def test_a_feature_gymnast_cannot_give_is_refused_by_name(lerobot_act):
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig

    from gymnast.policy.lerobot_features import LeRobotFeatures

    image, action = PolicyFeature(FeatureType.VISUAL, (3, 96, 96)), {"action": PolicyFeature(FeatureType.ACTION, (4,))}
    state = LeRobotFeatures.of(ACTConfig(input_features={"observation.image": image,
                                                         "observation.state": PolicyFeature(FeatureType.STATE, (6,))},
                                         output_features=action), "p")
    assert state.state_dim == 6
    with pytest.raises(ValueError, match=r"reads observation.state \(6,\), but this env gives no robot state"):
        state.batch(torch.zeros(1, 96, 96, 3, dtype=torch.uint8), ["reach the goal"])
    with pytest.raises(ValueError, match=r"observation.state of shape \(6,\), got states \(1, 4\)"):
        state.batch(torch.zeros(1, 96, 96, 3, dtype=torch.uint8), ["reach the goal"], torch.zeros(1, 4))
    cameras = ACTConfig(input_features={"observation.images.top": image, "observation.images.wrist": image,
                                        "observation.environment_state": PolicyFeature(FeatureType.ENV, (3,))},
                        output_features=action)
    with pytest.raises(ValueError, match=r"input feature observation.environment_state \(ENV"):
        LeRobotFeatures.of(cameras, "p")


def test_each_camera_feature_is_given_its_own_view_resized_to_its_declared_shape():
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig

    from gymnast.policy.lerobot_features import LeRobotFeatures, folder_cameras

    config = ACTConfig(input_features={"observation.images.gripper": PolicyFeature(FeatureType.VISUAL, (3, 32, 32)),
                                       "observation.images.front": PolicyFeature(FeatureType.VISUAL, (3, 16, 16))},
                       output_features={"action": PolicyFeature(FeatureType.ACTION, (4,))})
    features = LeRobotFeatures.of(config, "p")
    assert features.cameras == ("gripper", "front") and features.image_size == 32
    assert folder_cameras({"input_features": {key: {"type": "VISUAL"} for key in config.input_features}}) == (
        "gripper", "front")
    gripper, front = torch.zeros(1, 32, 32, 3, dtype=torch.uint8), torch.full((1, 32, 32, 3), 255, dtype=torch.uint8)
    batch = features.batch(torch.cat([gripper, front], dim=2), ["reach the goal"])  # the policy's order, side by side
    assert batch["observation.images.gripper"].shape == (1, 3, 32, 32) and batch["observation.images.gripper"].max() == 0
    assert batch["observation.images.front"].shape == (1, 3, 16, 16)
    torch.testing.assert_close(batch["observation.images.front"], torch.ones(1, 3, 16, 16))
    with pytest.raises(ValueError, match=r"2 cameras side by side.*got \(1, 32, 33, 3\)"):
        features.batch(torch.zeros(1, 32, 33, 3, dtype=torch.uint8), ["reach the goal"])


def test_a_folder_without_a_lerobot_config_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match=f"lerobot:{tmp_path}: no config.json"):
        load_policy(f"lerobot:{tmp_path}")


def test_the_full_size_smolvla_backbone_has_smolvlm2_500m_s_published_sizes(tmp_path):
    """benchmarks/lerobot_gpu.py times SmolVLA at its real size; its VLM's config must say so
    (the 450 M-parameter model itself is built there, on a GPU machine)."""
    from gymnast.policy.lerobot_init import SMOLVLM2_500M, write_vlm

    folder = write_vlm(tmp_path / "vlm", SMOLVLM2_500M)
    from transformers import AutoConfig, AutoProcessor  # after write_vlm has let transformers import torchvision

    config = AutoConfig.from_pretrained(folder)
    text, vision = config.text_config, config.vision_config
    assert (text.hidden_size, text.num_hidden_layers, text.num_attention_heads, text.num_key_value_heads,
            text.intermediate_size, text.vocab_size) == (960, 32, 15, 5, 2560, 49280)
    assert (vision.hidden_size, vision.num_hidden_layers, vision.image_size, vision.patch_size) == (768, 12, 512, 16)
    assert config.scale_factor == 4 and SMOLVLM2_500M.image_tokens == 64
    processor = AutoProcessor.from_pretrained(folder)
    assert processor.image_seq_len == 64 and processor.tokenizer("reach the goal")["input_ids"]
