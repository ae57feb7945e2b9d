"""`gymnast collect --replay SRC`: a recorded dataset's episodes again, seen through other cameras
or at another image size.

A view or a resolution chosen after the data was recorded (a gripper camera for the judge, 128 px
instead of 96) would otherwise mean recording new episodes, which for a policy's own rollouts are
not even the same episodes: the policy acts on what it sees, so at another image size it acts
otherwise. Meta-World is deterministic, so executing an episode's recorded actions from the scene
of its seed plays the very same episode again; only what the cameras render changes. Every
replayed episode is checked against its recording step by step (the robot's state, success, the
instruction) and a replay that departs from it is refused by name, so a dataset recorded under
another version of the simulator never passes for the same episodes.

The new dataset keeps each episode's recipe (task, behaviour, noise, seed), so a rerun resumes
where it stopped, and the source's horizon, end at success and sim-to-real gap; the cameras, the
image size and the front camera's pose are the command's.

Only datasets gymnast recorded can be replayed: they name the seed of every scene (their
``gymnast_collect.json`` says how they were recorded).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gymnast.config import CameraPose, EnvConfig
from gymnast.data.collect import SETTINGS_FILE, CollectConfig, EpisodeJob, check_settings, record_episode, record_plan
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import Episode, EpisodeColumns
from gymnast.envs.engine import ReplayActor
from gymnast.envs.gap import get_gap
from gymnast.utils.atomic import read_json

logger = logging.getLogger(__name__)

STATE_TOLERANCE = 1e-5
"""Largest difference in the robot's state (metres, gripper opening) a replay may show against its
recording; a deterministic replay shows none."""


def replay_dataset(source: str | Path, out: str | Path, config: CollectConfig, progress: bool = True) -> dict:
    """Records every episode of `source` again into `out` by executing its actions, under
    `config.env`'s cameras, image size and front camera; returns the new dataset's success table.

    Args:
        source: a dataset gymnast recorded (`gymnast collect`, `--policy` included).
        out: dataset directory (created if missing); episodes already there are skipped.
        config: the cameras and image size (`config.env`), workers, runner and flush interval;
            the tasks, episode counts, noise levels and seeds are the source's.
        progress: show a progress bar.

    Raises:
        FileNotFoundError: `source` has no settings file, so its scenes are unknown.
        ValueError: `out` is `source`, or holds a dataset recorded with other settings; an episode
            of `source` replays differently from its recording (the message names it).
    """
    source, out = Path(source), Path(out)
    if out.resolve() == source.resolve():
        raise ValueError(f"--replay {source} would record into itself; give another --out")
    recorded = _recorded_settings(source)
    env = dataclasses.replace(config.env, horizon=recorded.env.horizon,
                              terminate_on_success=recorded.env.terminate_on_success)
    config = dataclasses.replace(config, gap=recorded.gap, env=env)
    check_settings(out, config)
    variant = get_gap(config.gap).env_variant
    plan = []
    for i, info in enumerate(EpisodeDataset(source).episodes):
        if info.env_variant != variant:
            raise ValueError(f"{source}: episode {i} was recorded in {info.env_variant!r}, but {source / SETTINGS_FILE} "
                             f"says gap {recorded.gap!r} ({variant!r})")
        plan.append(EpisodeJob(info.task, info.behaviour, info.noise, info.seed, config.gap, env))
    logger.info("replaying %d episodes of %s in cameras %s at %d px", len(plan), source, ",".join(env.cameras),
                env.image_size)
    return record_plan(plan, ReplayEpisode(str(source.resolve())), out, config, progress)


@dataclass(frozen=True)
class ReplayEpisode:
    """Records one job by replaying the source episode of the same recipe, and checks the replay.

    Plain settings, so it pickles to the worker processes, which open the source once each.
    """

    source: str

    def __call__(self, job: EpisodeJob) -> Episode:
        dataset, index = _open_source(self.source)
        i = index[job.key]
        recording = dataset.columns(i)
        episode = record_episode(job, make_actor=lambda _: ReplayActor(recording.actions))
        check_replay(episode, recording, f"{self.source}: episode {i} ({job.task}, {job.behaviour}, seed {job.seed})")
        return episode


def check_replay(episode: Episode, recording: EpisodeColumns, where: str) -> None:
    """Raises ValueError naming `where` unless `episode` replays `recording`: the same length,
    robot states within `STATE_TOLERANCE`, the same success at every step and the same instruction."""
    if len(episode.actions) != len(recording.actions):
        raise ValueError(f"{where} ended after {len(episode.actions)} of its {len(recording.actions)} recorded actions "
                         "when replayed; it was recorded in another version of the simulator or with another horizon")
    gap = np.abs(episode.states - recording.states).max(axis=1)
    if (gap > STATE_TOLERANCE).any():
        step = int(np.argmax(gap > STATE_TOLERANCE))
        raise ValueError(f"{where} departs from its recording at step {step} when replayed (the robot's state differs "
                         f"by {gap[step]:.2e}); it was recorded in another version of the simulator")
    if not np.array_equal(episode.successes, recording.successes):
        step = int(np.argmax(episode.successes != recording.successes))
        raise ValueError(f"{where} replays with another success at step {step} than recorded")
    if episode.info.instruction != recording.info.instruction:
        raise ValueError(f"{where} was recorded with the instruction {recording.info.instruction!r}, "
                         f"the replay gets {episode.info.instruction!r}")


@functools.lru_cache(maxsize=2)
def _open_source(source: str) -> tuple[EpisodeDataset, dict[str, int]]:
    dataset = EpisodeDataset(source)
    return dataset, {info.key: i for i, info in enumerate(dataset.episodes)}


def _recorded_settings(source: Path) -> CollectConfig:
    path = source / SETTINGS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: only a dataset gymnast recorded can be replayed, because its "
                                "settings and episode seeds say which scenes it shows")
    settings = read_json(path)
    try:
        env = settings["env"]
        camera = CameraPose(**{**env["camera"], "lookat": tuple(env["camera"]["lookat"])})
        config = EnvConfig(image_size=env["image_size"], horizon=env["horizon"],
                           terminate_on_success=env["terminate_on_success"], camera=camera,
                           cameras=tuple(env.get("cameras", EnvConfig().cameras)))
        return CollectConfig(gap=settings["gap"], env=config)
    except (KeyError, TypeError) as error:
        raise ValueError(f"{path}: unreadable settings ({error!r}); expected env.image_size, env.horizon, "
                         "env.terminate_on_success, env.camera and gap") from error
