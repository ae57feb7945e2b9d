"""The simulator vector env: equal to plain MetaWorldEnv episodes, independent ends, workers, options."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import gymnast  # noqa: F401  (sets MUJOCO_GL before Meta-World imports mujoco)
from gymnast.config import EnvConfig
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.sim_vector import SimVectorEnv, shared_simulator_processes

K = 5
# Long enough for reach-v3's expert on seed 3, and not a multiple of K, so that it cuts a chunk.
HORIZON = 42
SMALL = EnvConfig(image_size=32, horizon=HORIZON)
TASKS = ["reach-v3", "push-v3", "drawer-close-v3"]


@pytest.fixture(scope="module")
def env():
    """A three-episode env in this process; building Meta-World scenes is the slow part, so shared."""
    with SimVectorEnv(3, chunk_size=K, config=SMALL) as env:
        yield env


@pytest.fixture(scope="module")
def two_workers():
    """The same env over two worker processes (slices of 1 and 2 episodes); starting them is slow."""
    with SimVectorEnv(3, chunk_size=K, config=SMALL, workers=2) as env:
        yield env


@pytest.fixture(scope="module")
def plain():
    """``plain(task, config)``: a cached plain MetaWorldEnv to compare with."""
    envs: dict[tuple[str, EnvConfig], MetaWorldEnv] = {}

    def get(task: str, config: EnvConfig = SMALL) -> MetaWorldEnv:
        if (task, config) not in envs:
            envs[(task, config)] = MetaWorldEnv(task, config)
        return envs[(task, config)]

    yield get
    for plain_env in envs.values():
        plain_env.close()


def random_chunks(n: int, batch: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, size=(n, batch, K, 4)).astype(np.float32)


def run(env: SimVectorEnv, options: dict, chunks: np.ndarray) -> list:
    """Every output of a reset and the steps, for exact comparisons."""
    outputs = [env.reset(options=options)]
    outputs += [env.step(chunk) for chunk in chunks]
    return outputs


def test_spaces_and_metadata_mirror_the_imagined_env(env):
    assert env.single_observation_space["image"].shape == (32, 32, 3)
    assert env.observation_space["image"].shape == (3, 32, 32, 3)
    assert env.action_space.shape == (3, K, 4)
    assert env.metadata["autoreset_mode"] == AutoresetMode.DISABLED


def test_chunks_equal_plain_episodes_stepped_with_the_same_actions(env, plain):
    seeds = [3, 4, 5]
    chunks = random_chunks(2, 3)  # (n, B, K, A)
    obs, infos = env.reset(options={"tasks": TASKS, "seeds": seeds, "frames": "ignored"})
    steps = [env.step(chunk) for chunk in chunks]
    assert env.observation_space.contains(obs) and all(env.observation_space.contains(s[0]) for s in steps)
    assert list(infos["task"]) == TASKS and list(infos["seed"]) == seeds
    assert list(infos["step"]) == [0, 0, 0] and not infos["success"].any()
    for i, (task, seed) in enumerate(zip(TASKS, seeds)):
        start, info = plain(task).reset(seed=seed)
        np.testing.assert_array_equal(obs["image"][i], start["image"])
        assert infos["instruction"][i] == info["instruction"]
        for chunk, (step_obs, rewards, terminated, truncated, step_infos) in zip(chunks, steps):
            results = [plain(task).step(action) for action in chunk[i]]
            expected = np.stack([r[0]["image"] for r in results])
            np.testing.assert_array_equal(step_infos["frames"][i], expected)
            np.testing.assert_array_equal(step_obs["image"][i], expected[-1])
            np.testing.assert_array_equal(step_infos["rewards"][i], [r[1] for r in results])
            # the full simulator state after each action, as the plain env's info gives it
            np.testing.assert_allclose(step_infos["env_states"][i], [r[4]["env_state"] for r in results], rtol=1e-6)
            assert rewards[i] == pytest.approx(sum(r[1] for r in results))
            assert step_infos["executed"][i] == K and not terminated[i] and not truncated[i]
        assert steps[-1][4]["step"][i] == 2 * K


def test_the_software_simulator_gap_reaches_every_episode():
    chunk = random_chunks(1, 1)[0]
    with SimVectorEnv(1, chunk_size=K, config=SMALL, gap="mild") as env:
        obs, _ = env.reset(options={"tasks": ["push-v3"], "seeds": [0]})
        _, _, _, _, infos = env.step(chunk)
    sim = MetaWorldEnv("push-v3", SMALL, gap="mild")
    np.testing.assert_array_equal(obs["image"][0], sim.reset(seed=0)[0]["image"])
    np.testing.assert_array_equal(infos["frames"][0], [sim.step(action)[0]["image"] for action in chunk[0]])
    sim.close()


def test_instructions_can_be_given_and_the_same_task_can_run_twice(env, plain):
    options = {"tasks": ["reach-v3", "reach-v3", "push-v3"], "seeds": [1, 2, 1], "instructions": ["a", "b", "c"]}
    _, infos = env.reset(options=options)
    assert list(infos["instruction"]) == ["a", "b", "c"]
    chunk = random_chunks(1, 3)[0]
    _, _, _, _, step_infos = env.step(chunk)
    assert list(step_infos["instruction"]) == ["a", "b", "c"]
    for i, seed in enumerate([1, 2]):  # two reach episodes at once, each its own
        plain("reach-v3").reset(seed=seed)
        expected = [plain("reach-v3").step(action)[0]["image"] for action in chunk[i]]
        np.testing.assert_array_equal(step_infos["frames"][i], expected)


def test_chunks_are_cut_at_the_horizon_and_the_episodes_stay_truncated(env, plain):
    chunks = random_chunks(10, 3)  # 8 whole chunks, 2 actions of the 9th reach the horizon, a 10th
    env.reset(options={"tasks": TASKS, "seeds": [0, 1, 2]})
    steps = [env.step(chunk) for chunk in chunks]
    for _, _, terminated, truncated, infos in steps[:8]:
        assert (infos["executed"] == K).all() and not truncated.any() and not terminated.any()
    _, reward, terminated, truncated, infos = steps[8]
    assert (infos["executed"] == 2).all() and (infos["step"] == HORIZON).all()
    assert truncated.all() and not terminated.any()
    assert np.isfinite(infos["rewards"][:, :2]).all() and np.isnan(infos["rewards"][:, 2:]).all()
    np.testing.assert_allclose(reward, infos["rewards"][:, :2].sum(axis=1))
    np.testing.assert_array_equal(infos["frames"][:, 2:], np.repeat(infos["frames"][:, 1:2], K - 2, axis=1))
    plain("push-v3").reset(seed=1)
    last = [plain("push-v3").step(action) for action in chunks[:, 1].reshape(-1, 4)[:HORIZON]][-2:]
    assert last[-1][3]  # the plain env truncates at the same action
    np.testing.assert_array_equal(infos["frames"][1, :2], [result[0]["image"] for result in last])
    _, reward, terminated, truncated, infos = steps[9]  # ended episodes are no longer stepped
    assert (infos["executed"] == 0).all() and (reward == 0).all() and (infos["step"] == HORIZON).all()
    assert truncated.all() and not terminated.any() and np.isnan(infos["rewards"]).all()
    np.testing.assert_array_equal(infos["frames"], np.repeat(steps[8][4]["frames"][:, -1:], K, axis=1))


def test_a_successful_episode_terminates_and_is_frozen_while_the_others_run_on(env, plain):
    expert = ScriptedExpert("reach-v3")
    _, info = plain("reach-v3").reset(seed=3)
    actions, terminated = [], False
    while not terminated:  # the expert's episode, replayed below through the vector env
        actions.append(expert(info["env_state"]))
        _, _, terminated, truncated, info = plain("reach-v3").step(actions[-1])
        assert not truncated
    n = len(actions)
    padded = np.zeros((-(-n // K) + 1, K, 4), np.float32)  # one more chunk after the success
    padded.reshape(-1, 4)[:n] = actions
    chunks = random_chunks(len(padded), 3, seed=1)
    chunks[:, 0] = padded
    env.reset(options={"tasks": TASKS, "seeds": [3, 3, 3]})
    steps = [env.step(chunk) for chunk in chunks]
    *_, (_, _, success_terminated, _, success_infos), (_, reward, terminated, truncated, infos) = steps
    assert success_terminated[0] and success_infos["success"][0] and success_infos["step"][0] == n
    assert success_infos["executed"][0] == n - (len(padded) - 2) * K
    assert not any(s[2][0] for s in steps[:-2])  # not before
    assert terminated[0] and not truncated[0] and infos["success"][0] and reward[0] == 0.0
    assert infos["executed"][0] == 0 and np.isnan(infos["rewards"][0]).all() and np.isnan(infos["env_states"][0]).all()
    np.testing.assert_array_equal(infos["frames"][0], np.repeat(success_infos["frames"][0, -1:], K, axis=0))
    assert infos["executed"][1] > 0 and infos["step"][1] == min(len(padded) * K, HORIZON)  # push ran on


def test_two_workers_give_exactly_the_outputs_of_one(env, two_workers):
    options = {"tasks": TASKS, "seeds": [5, 6, 7]}
    chunks = random_chunks(2, 3)
    expected = run(env, options, chunks)
    got = run(two_workers, options, chunks)
    again = run(two_workers, options, chunks)  # cached envs, reset again
    for one, two, three in zip(expected, got, again):
        for a, b, c in zip(one, two, three):
            if isinstance(a, dict):
                assert a.keys() == b.keys() == c.keys()
                for key in a:
                    np.testing.assert_array_equal(a[key], b[key], err_msg=key)
                    np.testing.assert_array_equal(a[key], c[key], err_msg=key)
            else:
                np.testing.assert_array_equal(a, b)
                np.testing.assert_array_equal(a, c)


def test_a_dead_worker_raises_runtime_error_and_close_is_idempotent(two_workers):
    two_workers.reset(options={"tasks": TASKS, "seeds": [0, 1, 2]})
    os.kill(two_workers.workers.pids()[1], signal.SIGKILL)  # the fixture's last use: it cannot recover
    with pytest.raises(RuntimeError, match="worker 1 failed in step"):
        two_workers.step(random_chunks(1, 3)[0])
    two_workers.close()
    two_workers.close()
    with pytest.raises(RuntimeError, match="closed"):
        two_workers.reset(options={"tasks": TASKS, "seeds": [0, 1, 2]})


def test_inside_a_shared_block_closed_envs_pass_their_workers_to_the_next_env_of_the_same_settings(env):
    options = {"tasks": TASKS, "seeds": [5, 6, 7]}
    chunks = random_chunks(2, 3)
    expected = run(env, options, chunks)
    with shared_simulator_processes():
        with SimVectorEnv(3, chunk_size=K, config=SMALL, workers=2) as first:
            pids, kept = first.workers.pids(), first.workers
            run(first, options, random_chunks(1, 3, seed=1))
            assert kept.call_each("scenes", [(), ()]) == [1, 2]
        assert kept.call_each("scenes", [(), ()]) == [0, 0]  # idle, the processes hold no scenes
        with SimVectorEnv(3, chunk_size=K, config=SMALL, workers=2) as second:
            assert second.workers.pids() == pids  # the same processes, no new start
            with SimVectorEnv(3, chunk_size=K, config=SMALL, workers=2) as third:  # open beside it: its own
                assert not set(third.workers.pids()) & set(pids)
            got = run(second, options, chunks)  # exactly what fresh episodes give
            for one, two in zip(expected, got):
                for a, b in zip(one, two):
                    for key in a if isinstance(a, dict) else [None]:
                        np.testing.assert_array_equal(a if key is None else a[key], b if key is None else b[key])
        with SimVectorEnv(3, chunk_size=K, config=SMALL, workers=2) as failing:
            assert failing.workers.pids() == pids
            os.kill(pids[1], signal.SIGKILL)
            with pytest.raises(RuntimeError, match="worker 1 failed"):
                failing.reset(options=options)
        with SimVectorEnv(3, chunk_size=K, config=SMALL, workers=2) as fresh:  # the failed workers were not kept
            assert not set(fresh.workers.pids()) & set(pids)
            run(fresh, options, chunks[:1])
            idle, idle_pids = fresh.workers, fresh.workers.pids()
        with SimVectorEnv(3, chunk_size=K, config=EnvConfig(image_size=32, horizon=20), workers=2) as other:
            assert not set(other.workers.pids()) & set(idle_pids)  # other settings: other processes
            kept = other.workers
        with pytest.raises(RuntimeError, match="closed"):  # ... whose memory the idle ones gave up first
            idle.call_each("close", [(), ()])
    with pytest.raises(RuntimeError, match="closed"):  # the block's end stopped the processes it kept
        kept.call_each("close", [(), ()])


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"seeds": [0, 1]}, '"tasks": 2'),
        ({"tasks": ["reach-v3", "push-v3"]}, '"seeds": 2'),
        ({"tasks": ["reach-v3"], "seeds": [0, 1]}, '"tasks": 2'),
        ({"tasks": "reach-v3", "seeds": [0, 1]}, '"tasks": 2'),
        ({"tasks": ["reach-v3", "push-v3"], "seeds": [0, 1, 2]}, '"seeds": 2'),
        ({"tasks": ["reach-v3", "push-v3"], "seeds": [0, "1"]}, '"seeds" must be 2'),
        ({"tasks": ["reach-v3", "push-v3"], "seeds": [0, -1]}, '"seeds" must be 2'),
        ({"tasks": ["reach-v3", 3], "seeds": [0, 1]}, '"tasks" must be 2'),
        ({"tasks": ["reach-v3", "push-v3"], "seeds": [0, 1], "instructions": ["a"]}, '"instructions": 2'),
        ({"tasks": ["reach-v3", "pushy-v3"], "seeds": [0, 1]}, "unknown task 'pushy-v3'"),
    ],
)
def test_bad_reset_options_raise_value_errors_naming_the_field(options, field):
    with SimVectorEnv(2, chunk_size=K, config=SMALL) as env, pytest.raises(ValueError, match=field):
        env.reset(options=options)


def test_step_before_reset_raises():
    with SimVectorEnv(2, chunk_size=K, config=SMALL) as env, pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((2, K, 4), np.float32))


def test_step_checks_the_action_shape_and_values(env):
    env.reset(options={"tasks": TASKS, "seeds": [0, 1, 2]})
    with pytest.raises(ValueError, match=r"\(3, 5, 4\), got \(3, 4, 4\)"):
        env.step(np.zeros((3, K - 1, 4), np.float32))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full((3, K, 4), np.nan, np.float32))


def test_the_environment_cache_stays_bounded_as_task_mixes_change():
    from gymnast.envs.sim_vector import _Episodes

    episodes = _Episodes(EnvConfig(image_size=32, horizon=5), "none", "train")
    mixes = [["reach-v3", "reach-v3"], ["push-v3", "push-v3"], ["drawer-open-v3", "door-open-v3"], ["reach-v3", "push-v3"],
             ["window-open-v3", "window-open-v3"]]
    try:
        for seed, tasks in enumerate(mixes):
            first = episodes.reset(tasks, [seed] * 2, [None] * 2)["image"]
            assert len(episodes._envs) <= 4  # twice the two episodes of a reset
            again = episodes.reset(tasks, [seed] * 2, [None] * 2)["image"]
            np.testing.assert_array_equal(first, again)  # a rebuilt or cached env starts the same scene
    finally:
        episodes.close()
