"""Rollouts in the imagined env and in a simulator have one shape and one meaning."""

import math

import numpy as np
import torch
from rl_helpers import POLICY, WORLD_MODEL

from gymnast.config import EnvConfig
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.policy.load import load_policy
from gymnast.rl.rollout import collect_rollouts, dataset_starts
from gymnast.world_model.base import load_world_model


def _check_consistent(rollouts, horizon, chunk):
    calls = math.ceil(horizon / chunk)
    count = len(rollouts.starts)
    assert rollouts.observations.shape[:2] == (count, calls) and rollouts.tokens.shape == (count, calls, 20)
    executed = rollouts.token_mask[:, :, ::4].sum(dim=(1, 2))  # one token per action dimension
    assert torch.equal(executed, rollouts.lengths)
    assert rollouts.frames.shape[1] == rollouts.actions.shape[1] + 1
    for r, length in enumerate(rollouts.lengths.tolist()):
        assert torch.all(rollouts.actions[r, length:] == 0)
        assert torch.all(rollouts.frames[r, length + 1:] == rollouts.frames[r, length])


def test_imagined_rollouts_run_to_the_horizon_and_carry_no_simulator_verdict(rl_dataset):
    policy, model = load_policy(POLICY), load_world_model(WORLD_MODEL)
    starts = dataset_starts(rl_dataset)
    env = BatchedImaginedEnv(model, len(starts), policy.chunk_size, horizon=12)
    rollouts = collect_rollouts(env, policy, starts, 1.0, torch.Generator().manual_seed(0))
    _check_consistent(rollouts, 12, policy.chunk_size)
    assert rollouts.lengths.tolist() == [12, 12] and rollouts.success is None and rollouts.env_rewards is None
    np.testing.assert_array_equal(rollouts.frames[:, 0].numpy(), np.stack([s.frames[-1] for s in starts]))


def test_simulator_rollouts_end_on_their_own_and_are_padded_to_one_shape(rl_dataset):
    policy = load_policy(POLICY)
    starts = dataset_starts(rl_dataset)
    with SimVectorEnv(len(starts), policy.chunk_size, EnvConfig(image_size=96, horizon=150)) as env:
        rollouts = collect_rollouts(env, policy, starts, 0.0, torch.Generator(), calls=30)
    _check_consistent(rollouts, 150, policy.chunk_size)
    assert torch.equal(rollouts.lengths < 150, rollouts.success)  # success ends an episode; failure runs to the horizon
    for r, length in enumerate(rollouts.lengths.tolist()):
        assert torch.isfinite(rollouts.env_rewards[r, :length]).all() and torch.isnan(rollouts.env_rewards[r, length:]).all()


def test_the_same_generator_state_gives_the_same_rollouts(rl_dataset):
    policy, model = load_policy(POLICY), load_world_model(WORLD_MODEL)
    starts = dataset_starts(rl_dataset)
    env = BatchedImaginedEnv(model, len(starts), policy.chunk_size, horizon=10)
    first = collect_rollouts(env, policy, starts, 1.0, torch.Generator().manual_seed(3))
    second = collect_rollouts(env, policy, starts, 1.0, torch.Generator().manual_seed(3))
    assert torch.equal(first.tokens, second.tokens) and torch.equal(first.frames, second.frames)
