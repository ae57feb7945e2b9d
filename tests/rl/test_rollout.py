"""Rollouts in the imagined env and in a simulator have one shape and one meaning."""

import math

import numpy as np
import torch
from gymnasium.vector import VectorWrapper
from rl_helpers import POLICY, WORLD_MODEL

from gymnast.config import EnvConfig
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.policy.load import load_policy
from gymnast.reward.sim import SimDense, SimSuccess
from gymnast.rl.rollout import collect_rollouts, concat_rollouts, dataset_starts, score_groups
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


def test_simulator_rollouts_without_frames_inside_chunks_keep_each_chunk_once_and_read_as_before(rl_dataset):
    policy = load_policy(POLICY)
    starts = dataset_starts(rl_dataset)
    chunk, made = policy.chunk_size, {}
    for every_frame in (True, False):
        with SimVectorEnv(len(starts), chunk, EnvConfig(image_size=96, horizon=40)) as env:
            made[every_frame] = collect_rollouts(env, policy, starts, 0.0, torch.Generator(), calls=8,
                                                 every_frame=every_frame)
    full, bare = made[True], made[False]
    assert full.hold == 1 and bare.hold == chunk
    assert bare.rendered.shape[1] == 1 + 8 and full.rendered.shape[1] == 1 + 8 * chunk
    _check_consistent(bare, 40, chunk)
    # One frame per action again: the frames the policy read (each chunk's last) held for its chunk.
    last_of_chunks = full.frames[:, chunk::chunk]  # (R, S, H, W, 3)
    assert torch.equal(bare.frames[:, 0], full.frames[:, 0])
    assert torch.equal(bare.frames[:, 1:], last_of_chunks.repeat_interleave(chunk, dim=1))
    assert torch.equal(bare.actions, full.actions) and torch.equal(bare.lengths, full.lengths)
    # Selecting and concatenating keep the frames as they are kept; mixed parts read one frame per action.
    first = bare.select(torch.tensor([1]))
    assert first.hold == chunk and torch.equal(first.frames, bare.frames[1:])
    both = concat_rollouts([bare, full])
    assert both.hold == 1 and torch.equal(both.frames, torch.cat([bare.frames, full.frames]))
    assert concat_rollouts([bare, bare]).hold == chunk
    # The simulator's rewards read no video: they are handed the frames as kept, and score as before.
    success, dense, blocks = _FrameCounting(), SimDense(), math.ceil(len(starts) / 2)
    assert torch.equal(score_groups(success, bare, 2), score_groups(success, full, 2))
    assert success.frame_counts == [1 + 8] * blocks + [1 + 8 * chunk] * blocks
    assert torch.equal(score_groups(dense, bare, 2), score_groups(dense, full, 2))
    torch.testing.assert_close(score_groups(dense, bare, 2, per_step=True), score_groups(dense, full, 2, per_step=True),
                               equal_nan=True)


class _FrameCounting(SimSuccess):
    """The simulator's success, noting how many frames of each rollout it was handed."""

    def __init__(self) -> None:
        self.frame_counts = []

    def score(self, frames, instructions, context):
        self.frame_counts.append(frames.shape[1])
        return super().score(frames, instructions, context)


def test_imagined_rollouts_asked_for_no_frames_inside_chunks_keep_every_frame(rl_dataset):
    policy, model = load_policy(POLICY), load_world_model(WORLD_MODEL)
    starts = dataset_starts(rl_dataset)
    env = BatchedImaginedEnv(model, len(starts), policy.chunk_size, horizon=10)
    rollouts = collect_rollouts(env, policy, starts, 1.0, torch.Generator().manual_seed(3), every_frame=False)
    # A world model imagines every frame whatever it is asked: nothing is repeated, so nothing is dropped.
    assert rollouts.hold == 1 and rollouts.rendered.shape[1] == 11


class _FirstChunkHeld(VectorWrapper):
    """A simulator that showed only its first chunk's last frame, then every frame of the others."""

    def reset(self, *, seed=None, options=None):
        self.chunks = 0
        return self.env.reset(seed=seed, options=options | {"every_frame": True})

    def step(self, actions):
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        if self.chunks == 0:
            infos = infos | {"frames": np.repeat(infos["frames"][:, -1:], infos["frames"].shape[1], axis=1)}
        self.chunks += 1
        return obs, rewards, terminated, truncated, infos


def test_rollouts_whose_chunks_stop_repeating_keep_every_frame(rl_dataset):
    policy = load_policy(POLICY)
    starts, chunk = dataset_starts(rl_dataset), policy.chunk_size
    made = {}
    for name, wrap, every_frame in (("full", lambda env: env, True), ("mixed", _FirstChunkHeld, False)):
        with SimVectorEnv(len(starts), chunk, EnvConfig(image_size=96, horizon=20)) as env:
            made[name] = collect_rollouts(wrap(env), policy, starts, 0.0, torch.Generator(), calls=4,
                                          every_frame=every_frame)
    full, mixed = made["full"], made["mixed"]
    assert mixed.hold == 1 and mixed.rendered.shape[1] == 1 + 4 * chunk
    expected = full.frames.clone()
    expected[:, 1 : chunk + 1] = full.frames[:, chunk : chunk + 1]  # the first chunk: its last frame, held
    assert torch.equal(mixed.frames, expected)
