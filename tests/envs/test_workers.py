"""Workers on both runners (spawned processes, Ray actors): every job's result once, dead workers replaced."""

from __future__ import annotations

import importlib.util
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from gymnast.config import EnvConfig
from gymnast.envs.parallel import parallel_map
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.envs.workers import MAX_ATTEMPTS, Runner, parse_runner
from gymnast.eval.evaluate import EvalConfig, plan_episodes, run_episode

HAS_RAY = importlib.util.find_spec("ray") is not None
RUNNERS = ["local", pytest.param("ray", marks=pytest.mark.skipif(not HAS_RAY, reason="Ray is not installed"))]
CONFIG = EvalConfig(tasks="reach-v3,drawer-close-v3", episodes=3, videos_per_task=0,
                    env=EnvConfig(image_size=32, horizon=25))


@pytest.fixture(scope="module")
def ray_here():
    """A Ray on this machine with two cores, for this module's Ray tests."""
    if not HAS_RAY:
        yield
        return
    import ray

    from gymnast.envs.ray_workers import init_ray

    init_ray(num_cpus=2)
    # Ray's workers cannot import this test module, so its helpers travel by value.
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield
    ray.shutdown()


def _play(job):
    """An evaluation episode, after killing this worker process if `job` carries a marker not yet taken."""
    episode, marker = job
    if marker is not None and not os.path.exists(marker):
        Path(marker).touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return run_episode(episode)


def _key(record: dict) -> tuple[str, int]:
    return record["task"], record["seed"]


@pytest.mark.parametrize(
    ("spec", "runner"),
    [("local", Runner()), *([("ray", Runner(ray=True)), ("ray:ray://head:10001", Runner(True, "ray://head:10001"))]
                            if HAS_RAY else [])],
)
def test_runner_specs_parse(spec, runner):
    assert parse_runner(spec) == runner


@pytest.mark.parametrize("spec", ["", "ray:", "Ray", "spark"])
def test_a_bad_runner_names_itself_and_the_choices(spec):
    with pytest.raises(ValueError, match=f"local, ray or ray:ADDRESS.*got {spec!r}"):
        parse_runner(spec)
    with pytest.raises(ValueError, match="runner"):
        EvalConfig(runner=spec)


def test_without_ray_a_ray_runner_names_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # what an environment without Ray looks like to imports
    with pytest.raises(ModuleNotFoundError, match=r"world-gymnast\[ray\]"):
        parse_runner("ray:auto")
    assert parse_runner("local") == Runner()


@pytest.mark.slow
@pytest.mark.parametrize("runner", RUNNERS)
def test_an_evaluation_whose_worker_is_killed_returns_every_episode_once_as_the_serial_run(runner, ray_here, tmp_path):
    episodes = plan_episodes(CONFIG, "expert", tmp_path)
    serial = [run_episode(episode) for episode in episodes]
    marker = str(tmp_path / "killed")
    # The third episode kills its worker, while the other worker is busy: both have played some.
    jobs = [(episode, marker if i == 2 else None) for i, episode in enumerate(episodes)]
    records = list(parallel_map(_play, jobs, 2, runner))
    assert os.path.exists(marker)
    assert len(records) == len(serial)
    assert sorted(records, key=_key) == sorted(serial, key=_key)


@pytest.mark.slow
@pytest.mark.parametrize("runner", RUNNERS)
def test_a_job_that_kills_every_worker_is_given_up_naming_it(runner, ray_here):
    with pytest.raises(RuntimeError, match=f"SIGKILL.* lost its worker {MAX_ATTEMPTS} times"):
        list(parallel_map(signal.raise_signal, [signal.SIGKILL, signal.SIGKILL], 2, runner))


@pytest.mark.parametrize("runner", RUNNERS)
def test_a_job_error_reaches_the_caller_as_itself(runner, ray_here):
    with pytest.raises(ValueError, match="'x7'") as raised:
        list(parallel_map(int, ["x7", "8"], 2, runner))
    assert "in the worker process" in str(raised.value.__cause__)


@pytest.mark.slow
@pytest.mark.skipif(not HAS_RAY, reason="Ray is not installed")
def test_the_vector_env_on_ray_actors_steps_as_in_this_process(ray_here):
    options = {"tasks": ["reach-v3", "push-v3", "reach-v3"], "seeds": [0, 1, 2]}
    chunks = np.random.default_rng(0).uniform(-1, 1, (3, 3, 2, 4)).astype(np.float32)  # (steps, B, K, A)
    runs = []
    for workers, runner in ((1, "local"), (2, "ray")):
        with SimVectorEnv(3, chunk_size=2, config=EnvConfig(image_size=32, horizon=5), workers=workers,
                          runner=runner) as env:
            obs, info = env.reset(options=options)
            runs.append([obs["image"], info["instruction"], *(env.step(chunk)[:4] for chunk in chunks)])
    for here, there in zip(*runs):
        if isinstance(here, tuple):  # (obs, rewards, terminated, truncated)
            np.testing.assert_array_equal(here[0]["image"], there[0]["image"])
            for a, b in zip(here[1:], there[1:]):
                np.testing.assert_array_equal(a, b)
        else:
            np.testing.assert_array_equal(here, there)
