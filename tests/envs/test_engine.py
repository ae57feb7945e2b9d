"""The rollout engine: what an episode records, replays, and one outcome for both drivers."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from gymnast.config import EnvConfig
from gymnast.envs.engine import RECORDABLE, ReplayActor, ScriptedActor, play_episode, run_batch
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.sim_vector import SimVectorEnv

ENV = EnvConfig(image_size=32, horizon=20)


@pytest.fixture(scope="module")
def env():
    with contextlib.closing(MetaWorldEnv("reach-v3", ENV)) as reach:
        yield reach


def test_an_episode_records_what_it_is_asked_for_start_first(env):
    run = play_episode(env, ScriptedActor(ScriptedExpert("reach-v3")), seed=3, record=RECORDABLE)
    assert run.done and run.steps == len(run.actions) <= ENV.horizon
    assert len(run.frames) == len(run.states) == len(run.env_states) == run.steps + 1
    assert len(run.rewards) == len(run.successes) == run.steps and run.success == any(run.successes)
    bare = play_episode(env, ScriptedActor(ScriptedExpert("reach-v3")), seed=3)
    assert bare.frames == bare.rewards == [] and np.array_equal(np.stack(bare.actions), np.stack(run.actions))


def test_replayed_actions_reproduce_the_episode_and_running_out_is_an_error(env):
    played = play_episode(env, ScriptedActor(ScriptedExpert("reach-v3")), seed=5, record=("frames",))
    replayed = play_episode(env, ReplayActor(np.stack(played.actions)), seed=5, record=("frames",))
    assert replayed.success == played.success and np.array_equal(np.stack(replayed.frames), np.stack(played.frames))
    with pytest.raises(ValueError, match="replayed actions ran out"):
        play_episode(env, ReplayActor(np.zeros((3, 4), np.float32)), seed=5)
    with pytest.raises(ValueError, match="cannot record"):
        play_episode(env, ReplayActor(np.zeros((3, 4), np.float32)), seed=5, record=("videos",))


def test_a_vector_env_and_a_single_episode_reach_the_same_outcome_from_the_same_actions(env):
    rng = np.random.default_rng(0)
    plan = rng.uniform(-1, 1, (2, 4 * 5, 4)).astype(np.float32)  # (R, T, A), T = the horizon
    chunks = iter(np.split(plan, 5, axis=1))
    with SimVectorEnv(2, chunk_size=4, config=ENV) as vector:
        results = list(run_batch(vector, lambda images, instructions, states: next(chunks),
                                 {"tasks": ["reach-v3"] * 2, "seeds": [1, 2]}))
    for i, seed in enumerate((1, 2)):
        single = play_episode(env, ReplayActor(plan[i]), seed, record=("frames", "rewards"))
        frames = np.concatenate([results[0].observation[i : i + 1]] + [r.frames[i] for r in results])
        assert np.array_equal(frames[: single.steps + 1], np.stack(single.frames))
        assert results[-1].success[i] == single.success
        assert sum(r.executed[i] for r in results) == single.steps


def test_an_episode_that_records_no_frames_renders_only_those_its_actor_reads(env):
    """Inside a chunk nobody looks at the frames: left unrendered (the costliest part of a step), the
    episode is the same and the actor reads the same frames."""
    rng = np.random.default_rng(1)
    plan = rng.uniform(-1, 1, (ENV.horizon, 4)).astype(np.float32)

    def chunked_actor(read: list):
        def act(_, obs):
            read.append(obs["image"])
            done = 4 * (len(read) - 1)  # chunks of 4 actions played so far
            return plan[done: done + 4]
        return act

    watched, bare = [], []
    recorded = play_episode(env, chunked_actor(watched), seed=7, record=("frames",))
    unrecorded = play_episode(env, chunked_actor(bare), seed=7)
    assert np.array_equal(np.stack(recorded.actions), np.stack(unrecorded.actions))
    assert recorded.success == unrecorded.success and recorded.steps == unrecorded.steps
    assert len(bare) == len(watched) and all(np.array_equal(a, b) for a, b in zip(bare, watched))
    assert unrecorded.obs["image"] is not None  # the episode's end is rendered
    _, *_ = env.reset(seed=7)
    obs, *_ = env.step(plan[0], observe=False)
    assert obs["image"] is None and obs["images"] is None and obs["state"].shape == (4,)
    observed, *_ = env.step(plan[1])
    unobserved_then_rendered = env.render()
    assert unobserved_then_rendered is observed["image"]  # render() is always the scene as it is now
    env.step(plan[2], observe=False)
    assert not np.array_equal(env.render(), observed["image"])  # drawn on demand, not the stale frame


def test_a_vector_env_asked_for_no_frames_inside_chunks_plays_the_same_episodes():
    rng = np.random.default_rng(2)
    plan = rng.uniform(-1, 1, (2, ENV.horizon, 4)).astype(np.float32)
    results = {}
    for every_frame in (True, False):
        chunks = iter(np.split(plan, 5, axis=1))
        with SimVectorEnv(2, chunk_size=4, config=ENV) as vector:
            results[every_frame] = list(run_batch(vector, lambda images, instructions, states: next(chunks),
                                                  {"tasks": ["reach-v3"] * 2, "seeds": [1, 2], "every_frame": every_frame}))
    for full, bare in zip(results[True], results[False]):
        # What the policy reads (each chunk's last frame), the rewards and the outcomes are the same.
        assert np.array_equal(full.observation, bare.observation) and np.array_equal(full.executed, bare.executed)
        assert np.array_equal(full.rewards, bare.rewards, equal_nan=True) and np.array_equal(full.success, bare.success)
        assert np.array_equal(bare.frames, np.repeat(full.frames[:, -1:], 4, axis=1))  # the last frame, repeated
