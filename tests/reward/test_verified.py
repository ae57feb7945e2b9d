"""The verified reward: 0 for the reference's own actions, lower the further the actions stray."""

from pathlib import Path

import pytest
import torch

from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.reward.base import RewardContext
from gymnast.reward.verified import VerifiedReward
from gymnast.world_model.base import load_world_model, rollout
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig

# The committed default world model (results/world_model/): a trained model, so that different
# actions really imagine different futures.
TRAINED = Path(__file__).parents[2] / "results" / "world_model" / "wm"


@pytest.fixture(scope="module")
def setting():
    model = load_world_model(TRAINED)
    env = MetaWorldEnv("reach-v3")
    start = torch.from_numpy(env.reset(seed=3)[0]["image"])[None, None]  # (1, 1, 96, 96, 3) a real frame
    env.close()
    reference = torch.linspace(-1, 1, 24 * 4).reshape(1, 24, 4).cos()  # (1, T, A) a smooth trajectory
    return model, VerifiedReward(model), start, reference


def imagine(model, start, actions):
    return rollout(model, start, actions=actions).frames


def test_the_reference_actions_themselves_score_zero(setting):
    model, reward, start, reference = setting
    score = reward.score(imagine(model, start, reference), ["reach"], RewardContext(start, reference))
    assert score.shape == (1,) and score.item() == pytest.approx(0.0, abs=1e-6)


def test_the_reward_falls_as_the_actions_diverge(setting):
    model, reward, start, reference = setting
    noise = torch.randn(1, 24, 4, generator=torch.Generator().manual_seed(0))
    scores = [reward.score(imagine(model, start, (reference + scale * noise).clamp(-1, 1)), ["reach"],
                           RewardContext(start, reference)).item() for scale in (0.0, 0.3, 1.0, 3.0)]
    assert scores[0] > scores[1] > scores[2] > scores[3]


def test_a_batch_scores_each_rollout_against_its_own_reference(setting):
    model, reward, start, reference = setting
    starts, references = start.expand(2, -1, -1, -1, -1), reference.expand(2, -1, -1)
    actions = torch.stack([reference[0], -reference[0]])  # the second rollout does the opposite
    scores = reward.score(imagine(model, starts, actions), ["reach"] * 2, RewardContext(starts, references))
    assert scores[0].item() == pytest.approx(0.0, abs=1e-6) and scores[1] < -0.01


def test_only_the_overlap_of_rollout_and_reference_is_compared(setting):
    model, reward, start, reference = setting
    longer = torch.cat([reference, -reference], dim=1)  # the reference stops after 24 steps
    assert reward.score(imagine(model, start, longer), ["reach"], RewardContext(start, reference)).item() == pytest.approx(0.0, abs=1e-6)
    empty = RewardContext(start, reference[:, :0])
    assert torch.isnan(reward.score(imagine(model, start, reference), ["reach"], empty)).all()


def test_missing_context_or_mismatched_batches_are_clear_errors():
    model = EmbeddedWorldModel(EmbeddedWorldModelConfig(image_size=32, latent_channels=16, widths=(8, 16), blocks=1, action_width=16))
    reward = VerifiedReward(model)
    frames = torch.zeros(2, 3, 32, 32, 3, dtype=torch.uint8)
    with pytest.raises(ValueError, match="needs RewardContext.start"):
        reward.score(frames, ["a", "b"], RewardContext())
    with pytest.raises(ValueError, match="same batch size"):
        reward.score(frames, ["a", "b"], RewardContext(torch.zeros(1, 1, 32, 32, 3, dtype=torch.uint8), torch.zeros(1, 3, 4)))


def test_a_group_sharing_its_reference_scores_as_each_rollout_would_alone(setting):
    model, reward, start, reference = setting
    noise = torch.randn(3, 24, 4, generator=torch.Generator().manual_seed(1))
    actions = (reference + 0.5 * noise).clamp(-1, 1)  # (3, T, A): a group of three rollouts
    frames = imagine(model, start.expand(3, -1, -1, -1, -1), actions)
    group = reward.score(frames, ["reach"] * 3, RewardContext(start.expand(3, -1, -1, -1, -1), reference.expand(3, -1, -1)))
    alone = torch.cat([reward.score(frames[i:i + 1], ["reach"], RewardContext(start, reference)) for i in range(3)])
    torch.testing.assert_close(group, alone, atol=1e-5, rtol=1e-5)
