"""The robot's state in imagination: a state model stepped beside the world model under the same
actions, for a policy that reads one."""

from pathlib import Path

import numpy as np
import pytest
import torch

from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.policy.text import InstructionEncoder
from gymnast.world_model.base import load_world_model
from gymnast.world_model.robot_state import ImaginedRobotState
from gymnast.world_model.state_model import load_state_models

RESULTS = Path(__file__).resolve().parents[2] / "results" / "world_model"
ENSEMBLE = RESULTS / "state_v5"  # two state models of Meta-World's 39-d environment state


def test_the_imagined_robot_state_is_the_members_mean_of_their_own_rollouts_first_dimensions():
    models = load_state_models(ENSEMBLE)
    generator = torch.Generator().manual_seed(0)
    starts = torch.randn(3, 39, generator=generator) * 0.1
    last = torch.rand(3, 4, generator=generator) * 2 - 1
    actions = torch.rand(3, 7, 4, generator=generator) * 2 - 1
    texts = ["reach the goal", "push the puck to the goal", "open the drawer"]
    robot = ImaginedRobotState(models, dim=4)
    first = robot.start(starts.numpy(), last.numpy(), texts)
    np.testing.assert_allclose(first, starts[:, :4].numpy(), atol=1e-6)  # a start is its recorded state
    robot.step(actions[:, :3].numpy())
    stepped = robot.step(actions[:, 3:].numpy())  # two steps of 3 and 4 actions: the same as 7 at once
    embedding = InstructionEncoder()(texts)
    expected = torch.stack([model.imagine(starts, actions, embedding, last).states[:, -1] for model in models]).mean(0)
    np.testing.assert_allclose(stepped, expected[:, :4].numpy(), atol=1e-5)
    with pytest.raises(ValueError, match="reads a 40-d robot state, the state model imagines 39-d"):
        ImaginedRobotState(models, dim=40)
    with pytest.raises(ValueError, match=r"3 recorded states of 39 dimensions, got \(3, 4\)"):
        robot.start(starts[:, :4].numpy(), last.numpy(), texts)


def test_the_batched_imagined_env_reports_the_robot_state_and_needs_the_starts_recorded_states():
    world_model = load_world_model(RESULTS / "wm")
    env = BatchedImaginedEnv(world_model, 2, chunk_size=5, horizon=10,
                             robot_state=ImaginedRobotState(load_state_models(ENSEMBLE), dim=4))
    frames = np.zeros((2, world_model.image_size, world_model.image_size, 3), np.uint8)
    states = [np.full(39, 0.1, np.float32), np.full(39, 0.2, np.float32)]
    options = {"frames": frames, "instructions": ["reach the goal"] * 2, "states": states,
               "prefixes": [np.zeros((0, 4), np.float32), np.ones((3, 4), np.float32)]}
    obs, _ = env.reset(seed=0, options=options)
    assert obs["state"].shape == (2, 4) and env.observation_space["state"].shape == (2, 4)
    np.testing.assert_allclose(obs["state"], [[0.1] * 4, [0.2] * 4], atol=1e-6)
    obs, *_ = env.step(np.full((2, 5, 4), 0.5, np.float32))
    assert obs["state"].shape == (2, 4) and not np.allclose(obs["state"], [[0.1] * 4, [0.2] * 4])
    with pytest.raises(ValueError, match="starts from each start's recorded state"):
        env.reset(seed=0, options={**options, "states": [np.zeros(0, np.float32)] * 2})
