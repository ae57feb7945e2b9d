"""Simulator rewards read what the simulator reported, from real Meta-World rollouts."""

import math

import numpy as np
import pytest
import torch

from gymnast.envs.experts import make_behaviour
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.reward.base import RewardContext
from gymnast.reward.sim import META_WORLD_MAX_STEP_REWARD, SimDense, SimSuccess

HORIZON = 150


def run(task: str, behaviour: str, seed: int = 1) -> tuple[bool, list[float]]:
    env = MetaWorldEnv(task)
    act = make_behaviour(behaviour, task, 0.0, seed)
    _, info = env.reset(seed=seed)
    rewards = []
    for _ in range(HORIZON):
        _, reward, terminated, truncated, info = env.step(act(info["env_state"]))
        rewards.append(reward)
        if terminated or truncated:
            break
    env.close()
    return bool(info["success"]), rewards


@pytest.fixture(scope="module")
def context() -> RewardContext:
    outcomes = [run("reach-v3", "expert"), run("reach-v3", "random")]
    rewards = np.full((2, HORIZON), np.nan)
    for i, (_, r) in enumerate(outcomes):
        rewards[i, : len(r)] = r
    return RewardContext(success=torch.tensor([s for s, _ in outcomes]), env_rewards=torch.from_numpy(rewards))


def test_success_is_what_the_simulator_said(context):
    assert SimSuccess().score(torch.empty(0), ["reach"] * 2, context).tolist() == [1.0, 0.0]


def test_the_dense_reward_prefers_the_expert_and_lies_in_zero_one(context):
    scores = SimDense().score(torch.empty(0), ["reach"] * 2, context)
    assert 0 <= scores[1] < scores[0] <= 1


def test_a_success_holds_the_maximum_reward_for_the_rest_of_the_horizon(context):
    rewards = context.env_rewards[0]
    steps = int((~torch.isnan(rewards)).sum())
    expected = (rewards[:steps].sum() + (HORIZON - steps) * META_WORLD_MAX_STEP_REWARD) / HORIZON / META_WORLD_MAX_STEP_REWARD
    assert steps < HORIZON  # the expert finished early
    assert math.isclose(SimDense().score(torch.empty(0), ["reach"] * 2, context)[0].item(), expected.item(), rel_tol=1e-5)


def test_rollouts_without_simulator_outcomes_are_a_clear_error():
    with pytest.raises(ValueError, match="RewardContext.success"):
        SimSuccess().score(torch.empty(0), ["x"], RewardContext())
    with pytest.raises(ValueError, match="RewardContext.env_rewards"):
        SimDense().score(torch.empty(0), ["x"], RewardContext())
