"""`gymnast collect`: record episodes in the real world into a LeRobot v3.0 dataset.

Legend: K action-chunk length, A action dimensions.

The plan is a deterministic list of episode recipes (task, behaviour, noise, seed), so a rerun
with the same arguments skips every recipe already in the dataset and records only the rest, and
a rerun with more episodes per task extends it. Finished episodes are staged durably as they
arrive (a crash loses at most the episodes in flight) and consolidated into the dataset files
every `flush_every` episodes and at the end.

Every episode is played by the rollout engine (`gymnast.envs.engine.play_episode`) with an
`Actor`, which returns a chunk of K actions executed open-loop: a scripted behaviour (expert,
noisy expert, failure) is a chunk of one action read from the simulator state. A learned policy's actor is built above this layer (data/ never imports the
policies) and passed in as an `ActorFactory`; see `gymnast.eval.record`.

Cameras: `EnvConfig.cameras` names the views recorded (``--cameras front,gripper``); each becomes a
video feature of the dataset, the first being the primary (`Episode.frames`; see
`gymnast.data.lerobot_writer`). The default, the front camera alone, records what collect always has.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from gymnast.config import CommaFloats, EnvConfig
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.lerobot_writer import LeRobotWriter
from gymnast.data.schema import Episode, EpisodeInfo, episode_key
from gymnast.envs.engine import RECORDABLE, Actor, ScriptedActor, play_episode
from gymnast.envs.experts import make_behaviour
from gymnast.envs.gap import get_gap
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.parallel import cached_env, parallel_map
from gymnast.envs.tasks import DATA_SEEDS, resolve_tasks
from gymnast.envs.workers import parse_runner
from gymnast.utils.atomic import read_json, write_json

logger = logging.getLogger(__name__)

SETTINGS_FILE = "gymnast_collect.json"
"""Beside the dataset: the environment settings it was recorded with, checked on every rerun."""


@dataclass(frozen=True)
class CollectConfig:
    """What to record."""

    tasks: str = "mt10"
    """Task names and/or task sets (mt10, mt50), comma-separated."""
    episodes_per_task: int = 10
    """Expert (or policy) episodes per task; they cycle through the noise levels."""
    noise: CommaFloats = (0.0, 0.1, 0.3)
    """Standard deviations of Gaussian action noise for the expert (or policy) episodes (0 = clean)."""
    failure_fraction: float = 0.25
    """Extra failure episodes per task (random actions, another task's expert), as a fraction of
    episodes_per_task, rounded up; 0 records none. Not used when recording a policy."""
    near_misses: int = 0
    """Near-miss episodes per task: the task's expert acting as if the objects and the goal were a
    few centimetres off, so its hand misses them and nothing moves (`gymnast.envs.experts`),
    on the same seeds as the expert episodes. Not used when recording a policy."""
    first_seed: int = 0
    """Seed of each task's first episode; episode i uses first_seed + i (data seeds only)."""
    gap: str = "none"
    """Record in the real world (none) or a software simulator (mild, strong)."""
    workers: int = 2
    """Processes that record episodes in parallel (one per core is best)."""
    runner: str = "local"
    """Where the worker processes run: local (spawned on this machine), ray (Ray actors on a Ray
    started here, or on the cluster in RAY_ADDRESS) or ray:ADDRESS (a Ray cluster, e.g. ray:auto or
    ray:ray://head:10001)."""
    flush_every: int = 50
    """Consolidate staged episodes into dataset files after this many."""
    env: EnvConfig = field(default_factory=EnvConfig)
    """Cameras, image size and horizon."""

    def __post_init__(self) -> None:
        if self.episodes_per_task < 0 or self.near_misses < 0:
            raise ValueError(f"episodes_per_task and near_misses must be >= 0, got {self.episodes_per_task} "
                             f"and {self.near_misses}")
        if not self.noise or any(n < 0 for n in self.noise):
            raise ValueError(f"noise must be one or more non-negative levels, got {self.noise}")
        last = self.first_seed + max(self.episodes_per_task, self.near_misses, 1) - 1
        if self.first_seed not in DATA_SEEDS or last not in DATA_SEEDS:
            raise ValueError(
                f"seeds {self.first_seed}..{last} leave the data seed range "
                f"[{DATA_SEEDS.start}, {DATA_SEEDS.stop}); evaluation seeds are never recorded"
            )
        parse_runner(self.runner)

    @property
    def failures_per_task(self) -> int:
        return math.ceil(self.episodes_per_task * self.failure_fraction)


@dataclass(frozen=True)
class EpisodeJob:
    """One episode's recipe: everything needed to record it, in any process."""

    task: str
    behaviour: str
    noise: float
    seed: int
    gap: str
    env: EnvConfig

    @property
    def key(self) -> str:
        return episode_key(get_gap(self.gap).env_variant, self.task, self.behaviour, self.noise, self.seed)


class ActorFactory(Protocol):
    """Builds each episode's `Actor` in the process that records it.

    It travels to the worker processes, so it must be picklable (an instance of a module-level
    class holding plain settings), and it should load anything heavy once per process.
    """

    behaviour: str
    """The behaviour recorded with every episode (``policy-<tag>``, see `gymnast.data.schema.policy_behaviour`)."""

    def __call__(self, job: EpisodeJob) -> Actor: ...


def plan_episodes(config: CollectConfig, behaviour: str | None = None) -> list[EpisodeJob]:
    """Every recipe the configuration asks for, in a fixed order.

    Args:
        config: tasks, episodes per task, noise levels, failures, seeds.
        behaviour: a learned actor's behaviour (`ActorFactory.behaviour`): every episode uses it,
            cycling through the noise levels, and no failure episodes are planned (the policy's
            own failures are what such a dataset is for). None plans the scripted behaviours.
    """
    jobs = []
    for task in resolve_tasks(config.tasks):
        for i in range(config.episodes_per_task):
            noise = config.noise[i % len(config.noise)]
            name = behaviour or ("expert" if noise == 0 else "noisy_expert")
            jobs.append(EpisodeJob(task, name, noise, config.first_seed + i, config.gap, config.env))
        for i in range(0 if behaviour else config.failures_per_task):
            failure = ("random", "wrong_task_expert")[i % 2]
            jobs.append(EpisodeJob(task, failure, 0.0, config.first_seed + i, config.gap, config.env))
        for i in range(0 if behaviour else config.near_misses):
            jobs.append(EpisodeJob(task, "near_miss_expert", 0.0, config.first_seed + i, config.gap, config.env))
    return jobs


def record_episode(job: EpisodeJob, make_actor: ActorFactory | None = None) -> Episode:
    """Runs one recipe to its end in this process's cached environment.

    Args:
        job: the recipe.
        make_actor: builds the episode's actor; None plays the scripted `job.behaviour`.

    Raises:
        ValueError: the actor returned something other than a non-empty (K, A) chunk.
    """
    env = cached_env(job.task, job.env, gap=job.gap)
    if make_actor is None:
        actor: Actor = ScriptedActor(make_behaviour(job.behaviour, job.task, job.noise, job.seed))
    else:
        actor = make_actor(job)
    recorder = _ViewRecorder(env) if len(job.env.cameras) > 1 else None
    run = play_episode(recorder or env, actor, job.seed, record=RECORDABLE)
    views = {} if recorder is None else {name: np.stack(frames) for name, frames in recorder.views.items()}
    return Episode(
        frames=views[job.env.cameras[0]] if views else np.stack(run.frames),
        states=np.stack(run.states),
        env_states=np.stack(run.env_states).astype(np.float32),
        actions=np.stack(run.actions).astype(np.float32),
        rewards=np.asarray(run.rewards, dtype=np.float32),
        successes=np.asarray(run.successes, dtype=bool),
        info=EpisodeInfo(
            task=job.task,
            instruction=run.instruction,
            success=run.success,
            behaviour=job.behaviour,
            noise=job.noise,
            seed=job.seed,
            env_variant=env.gap.env_variant,
        ),
        views=views,
    )


class _ViewRecorder:
    """The env as the rollout engine plays it, keeping every observation's camera views on the way.

    The engine records ``obs["image"]``, every view side by side; each view is kept here on its own
    from the very same observations, so every camera of an episode shows the same instants.
    """

    def __init__(self, env: MetaWorldEnv) -> None:
        self.env = env
        self.views: dict[str, list[np.ndarray]] = {name: [] for name in env.config.cameras}

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)  # what actors and the engine read: env_state, instruction, task

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._keep(obs)
        return obs, info

    def step(self, action):
        obs, *rest = self.env.step(action)
        self._keep(obs)
        return (obs, *rest)

    def _keep(self, obs: dict) -> None:
        for name, frame in obs["images"].items():
            self.views[name].append(frame)


def collect(
    config: CollectConfig, out: str | Path, progress: bool = True, make_actor: ActorFactory | None = None
) -> dict:
    """Records every planned episode not yet in `out`; returns `success_table` of the dataset.

    Args:
        config: what to record.
        out: dataset directory (created if missing).
        progress: show a progress bar with the running success rate.
        make_actor: records this actor (e.g. a learned policy) as `make_actor.behaviour` instead
            of the scripted behaviours; see `plan_episodes`.

    Raises:
        ValueError: `out` holds a dataset recorded with other environment settings.
    """
    out = Path(out)
    check_settings(out, config)
    plan = plan_episodes(config, None if make_actor is None else make_actor.behaviour)
    record = record_episode if make_actor is None else functools.partial(record_episode, make_actor=make_actor)
    return record_plan(plan, record, out, config, progress)


def record_plan(plan: list[EpisodeJob], record: Callable[[EpisodeJob], Episode], out: Path, config: CollectConfig,
                progress: bool = True) -> dict:
    """Records every job of `plan` not yet in `out` with `record` (in `config.workers` processes),
    staging each episode as it arrives; returns `success_table` of the dataset.

    The settings file of `out` must already have been checked (`check_settings`)."""
    writer = LeRobotWriter(out, fps=MetaWorldEnv.metadata["render_fps"], cameras=config.env.cameras)
    done = writer.keys()
    todo = [job for job in plan if job.key not in done]
    logger.info("%d episodes planned, %d of them already in %s", len(plan), len(plan) - len(todo), out)
    bar = tqdm(total=len(todo), desc="collect", unit="ep", disable=not progress)
    recorded = successes = 0
    try:
        for episode in parallel_map(record, todo, config.workers, config.runner):
            writer.add(episode)
            recorded += 1
            successes += episode.info.success
            bar.update()
            bar.set_postfix(success=f"{successes / recorded:.0%}")
            if writer.num_staged >= config.flush_every:
                writer.flush()
    finally:
        bar.close()
        writer.flush()
    return success_table(EpisodeDataset(out).episodes)


def success_table(episodes: list[EpisodeInfo]) -> dict:
    """{task: {behaviour: [successes, episodes]}} over a dataset's episodes."""
    table: dict = defaultdict(lambda: defaultdict(lambda: [0, 0]))
    for info in episodes:
        cell = table[info.task][info.behaviour]
        cell[0] += int(info.success)
        cell[1] += 1
    return {task: dict(row) for task, row in table.items()}


def check_settings(out: Path, config: CollectConfig) -> None:
    """Writes the environment settings beside a new dataset, or checks a dataset's against them.

    Raises:
        ValueError: `out` was recorded with other settings (the message names the field).
    """
    settings = {"env": dataclasses.asdict(config.env), "gap": config.gap}
    if config.env.cameras == EnvConfig().cameras:
        # Written as before cameras were a setting: one-camera datasets keep their bytes, and those
        # recorded then (no "cameras" in the file) resume.
        del settings["env"]["cameras"]
    path = out / SETTINGS_FILE
    if path.exists():
        recorded = read_json(path)
        current = json.loads(json.dumps(settings))  # tuples become lists, as in the file
        cameras = recorded.get("env", {}).get("cameras", list(EnvConfig().cameras))
        if cameras != list(config.env.cameras):
            raise ValueError(f"{path}: this dataset records cameras {','.join(cameras)}, not "
                             f"{','.join(config.env.cameras)}; rerun with --cameras {','.join(cameras)} or "
                             "record into a new directory")
        for name in current:
            if recorded.get(name) != current[name]:
                raise ValueError(
                    f"{path}: field {name!r} was {recorded.get(name)} when this dataset was recorded, "
                    f"now {current[name]}; record into a new directory instead"
                )
    else:
        write_json(path, settings)
