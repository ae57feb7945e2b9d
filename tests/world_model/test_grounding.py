"""A world model grounded in the state: every frame rendered at a state it is given (the recorded
one in training and in eval-wm, a state model's in imagination)."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from gymnast.cli import main
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.world_model.base import grounded_state_dim, load_world_model, rollout
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.robot_state import ImaginedRobotState, robot_state_in_imagination
from gymnast.world_model.state_model import load_state_models
from gymnast.world_model.train import WM_PRESETS, train_world_model
from gymnast.world_model.views import MultiViewWorldModel

TINY = dict(image_size=16, latent_channels=8, widths=(8, 8), blocks=1, action_width=8, bf16=False)
STATE_MODELS = Path(__file__).resolve().parents[2] / "results" / "world_model" / "state_v5"  # 39-d Meta-World states
CONTEXT = torch.randint(0, 256, (2, 2, 16, 16, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))


def grounded(**settings) -> EmbeddedWorldModel:
    torch.manual_seed(0)
    model = EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY, state_dim=3, state_mean=(0.0, 1.0, 2.0),
                                                        state_std=(1.0, 2.0, 3.0), **settings)).eval()
    with torch.no_grad():  # trained blocks respond to their condition; fresh ones start as the identity
        for block in model.blocks:
            block.conv2.weight.normal_(0, 0.3)
    return model


def frames(model, actions: torch.Tensor, states: torch.Tensor | None) -> torch.Tensor:
    grounding = {} if states is None else {"states": states}
    return model.step(model.init_state(CONTEXT), actions, **grounding)[1].float()


def test_a_grounded_fine_tune_starts_exactly_where_the_ungrounded_model_was():
    plain = EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY)).eval()
    model = grounded()
    plain.load_state_dict({k: v for k, v in model.state_dict().items() if not k.startswith("embed_state.")})
    actions = torch.rand(2, 4, 4) * 2 - 1
    for states in (torch.zeros(2, 4, 3), torch.randn(2, 4, 3) * 5):  # the state embedding starts at zero
        assert torch.equal(frames(model, actions, states), frames(plain, actions, None))


def test_a_grounded_model_draws_what_its_states_say_and_names_what_is_missing():
    model = grounded()
    with torch.no_grad():
        model.embed_state[2].weight.normal_()
    actions = torch.rand(2, 4, 4) * 2 - 1
    here, there = torch.zeros(2, 4, 3), torch.ones(2, 4, 3)
    assert not torch.equal(frames(model, actions, here), frames(model, actions, there))
    assert torch.equal(frames(model, actions, here), frames(model, actions, here.clone()))
    assert grounded_state_dim(model) == 3 and grounded_state_dim(EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY))) == 0
    with pytest.raises(ValueError, match=r"grounded: step\(\) needs states \(2, 4, 3\) float"):
        frames(model, actions, None)
    with pytest.raises(ValueError, match=r"states must be \(2, 4, 3\) float.*got \(2, 3, 3\)"):
        frames(model, actions, torch.zeros(2, 3, 3))
    with pytest.raises(ValueError, match="not grounded in a state"):
        frames(EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY)).eval(), actions, here)
    with pytest.raises(ValueError, match="needs that many state_mean and state_std"):
        EmbeddedWorldModelConfig(**TINY, state_dim=3, state_mean=(0.0,), state_std=(1.0,))
    # Several views are rendered at the same state; guidance without the action keeps the state.
    views = MultiViewWorldModel(model, ("front", "gripper"))
    assert views.state_dim == 3
    both = views.step(views.init_state(CONTEXT.repeat(1, 1, 1, 2, 1)), actions, states=here)[1]
    assert both.shape == (2, 4, 16, 32, 3)


def test_action_guidance_scales_the_action_and_keeps_the_state():
    model = grounded(action_dropout=0.1)
    with torch.no_grad():
        model.embed_state[2].weight.normal_()
        model.no_action.normal_()
    free = EmbeddedWorldModel(dataclasses.replace(model.config, guidance=0.0)).eval()  # the "no action" step alone
    free.load_state_dict(model.state_dict())
    actions, other = torch.rand(2, 4, 4) * 2 - 1, torch.rand(2, 4, 4) * 2 - 1
    here, there = torch.zeros(2, 4, 3), torch.ones(2, 4, 3)
    assert torch.equal(frames(free, actions, here), frames(free, other, here))
    assert not torch.equal(frames(free, actions, here), frames(free, actions, there))


def test_train_wm_grounded_learns_the_states_normalisation_then_eval_wm_renders_at_recorded_or_imagined_states(
        tiny_dataset, tmp_path):
    config = dataclasses.replace(WM_PRESETS["debug"], heldout_fraction=0.25, grounded=True, state_noise=0.1)
    train_world_model(tiny_dataset, tmp_path / "wm", config, progress=False)
    model = load_world_model(tmp_path / "wm")
    saved = json.loads((tmp_path / "wm" / "config.json").read_text())["model"]
    assert model.state_dim == saved["state_dim"] == 39  # Meta-World's environment state
    assert len(saved["state_mean"]) == 39 and min(saved["state_std"]) > 0
    train_world_model(tiny_dataset, tmp_path / "wm", dataclasses.replace(config, steps=6), resume=True, progress=False)
    # A grounded fine-tune of an ungrounded run keeps its weights and adds the state embedding.
    train_world_model(tiny_dataset, tmp_path / "plain", dataclasses.replace(config, grounded=False), progress=False)
    tuned = dataclasses.replace(config, init=tmp_path / "plain")
    train_world_model(tiny_dataset, tmp_path / "tuned", tuned, progress=False)
    assert load_world_model(tmp_path / "tuned").state_dim == 39
    for robot_state, states in ((None, "recorded"), (STATE_MODELS, "state_model")):
        out = tmp_path / f"eval_{states}.json"
        main(["eval-wm", "--wm", str(tmp_path / "wm"), "--data", str(tiny_dataset), "--out", str(out), "--videos", "0",
              "--control-scenes", "1", *(["--robot-state", str(robot_state)] if robot_state else [])])
        report = json.loads(out.read_text())
        assert report["grounding"]["states"] == states and report["psnr_h1"] > 0
        assert report["controllability"]["scenes"] == 1
    with pytest.raises(SystemExit):
        main(["eval-wm", "--wm", str(tmp_path / "plain"), "--data", str(tiny_dataset), "--out", str(tmp_path / "e.json"),
              "--robot-state", str(STATE_MODELS)])


def test_the_imagined_env_renders_a_grounded_model_at_the_state_models_states():
    model = grounded()
    world_model = EmbeddedWorldModel(dataclasses.replace(model.config, state_dim=39, state_mean=(), state_std=())).eval()
    with torch.no_grad():
        for block in world_model.blocks:
            block.conv2.weight.normal_(0, 0.3)
        world_model.embed_state[2].weight.normal_()
    with pytest.raises(ValueError, match="needs a robot_state"):
        BatchedImaginedEnv(world_model, 2, chunk_size=3, horizon=5)
    robot = ImaginedRobotState(load_state_models(STATE_MODELS), dim=0)  # the policy reads no state
    env = BatchedImaginedEnv(world_model, 2, chunk_size=3, horizon=5, robot_state=robot)
    start = CONTEXT[:, -1].numpy()
    states = [np.full(39, 0.1, np.float32), np.full(39, 0.2, np.float32)]
    options = {"frames": start, "instructions": ["reach the goal"] * 2, "states": states}
    obs, _ = env.reset(seed=0, options=options)
    assert "state" not in obs and "state" not in env.single_observation_space.spaces
    actions = np.random.default_rng(0).uniform(-1, 1, (2, 3, 4)).astype(np.float32)
    env.step(actions)
    last = np.random.default_rng(1).uniform(-1, 1, (2, 3, 4)).astype(np.float32)
    _, _, _, truncated, infos = env.step(last)  # cut at the horizon: 2 of the 3 actions
    assert truncated.all() and infos["frames"].shape[1] == 2
    # The same rollouts by hand: the state model's states after each action, the frames drawn there.
    reference = ImaginedRobotState(load_state_models(STATE_MODELS), dim=0)
    reference.start(np.stack(states), np.zeros((2, 4), np.float32), ["reach the goal"] * 2)
    both = np.concatenate([actions, last[:, :2]], axis=1)
    expected = rollout(world_model, torch.from_numpy(start)[:, None], torch.from_numpy(both), states=reference.imagine(both))
    np.testing.assert_array_equal(env.video()[:, 1:], expected.frames.numpy())
    with pytest.raises(ValueError, match="renders every frame at a 39-d state; give a state model"):
        robot_state_in_imagination(0, None, "runs/policy", "runs/wm", grounded=39)
    with pytest.raises(ValueError, match="renders at 12-d states, the state model .* imagines 39-d"):
        robot_state_in_imagination(0, STATE_MODELS, "runs/policy", "runs/wm", grounded=12)
