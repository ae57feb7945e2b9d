"""What an RL run trains from, read before it starts: the tasks a run without `--tasks` takes,
the dataset and the frame settings of the policy it starts from, and what a dataset recorded on
another robot cannot give.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from gymnast.data.lerobot import FeatureKeys
from gymnast.envs.tasks import resolve_tasks
from gymnast.policy.load import is_lerobot
from gymnast.rl.config import RLConfig, RLRun
from gymnast.rl.rollout import recorded_elsewhere, tasks_with_starts
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import resolve_checkpoint
from gymnast.utils.plugins import is_plugin


def with_tasks_from_data(run_spec: RLRun, config: RLConfig) -> RLConfig:
    """`config` for a run whose tasks were not named: the preset's tasks that its start-state
    dataset has, or else as many of the dataset's own (`tasks_with_starts`); fresh scenes need no
    dataset and keep the preset's, and named scenes name their own."""
    if config.fresh_scenes or config.scenes is not None:
        return config
    data, keys = Path(run_spec.data or policy_dataset(run_spec.policy)), policy_keys(run_spec.policy)
    if recorded_elsewhere(data, keys):
        return dataclasses.replace(config, tasks="")  # all of the other robot's own tasks
    return dataclasses.replace(config, tasks=",".join(tasks_with_starts(data, resolve_tasks(config.tasks), keys)))


def policy_dataset(policy_run: str | Path) -> str:
    """The dataset the policy was trained on (recorded in its config.json).

    Raises:
        ValueError: the run does not say.
    """
    for saved in _policy_configs(policy_run):
        if "data" in saved:
            return saved["data"]
    raise ValueError(f"{policy_run} does not say which dataset it was trained on; give the start states with --data DIR")


def policy_frames(policy_run: str | Path) -> dict:
    """How the policy's training frames were read: ``{"camera", "fit", "keys"}`` from its SFT settings
    (or an RL run's, which keeps them); {} for a run from before they were saved (the defaults)."""
    for saved in _policy_configs(policy_run):
        for section in ("frames", "sft"):
            if section in saved:
                return {key: saved[section][key] for key in ("camera", "fit", "keys") if key in saved[section]}
    return {}


def policy_keys(policy_run: str | Path) -> FeatureKeys:
    """The dataset features the policy learnt from as actions and states (`policy_frames`), which
    RL reads its start states and demonstrations by."""
    return FeatureKeys(**policy_frames(policy_run).get("keys", {}))


def _policy_configs(policy_run: str | Path) -> list[dict]:
    """The policy run's config.json, then its checkpoint's (whichever exist); none for a LeRobot
    folder or a user's own factory, which record neither the dataset nor gymnast's frame settings."""
    if is_lerobot(policy_run) or is_plugin(policy_run):
        return []
    checkpoint = resolve_checkpoint(Path(policy_run))
    paths = (Path(policy_run) / "config.json", checkpoint / "config.json")
    return [read_json(path) for path in paths if path.exists()]


def check_other_robot(data: Path, env, config: RLConfig) -> None:
    """Raises ValueError, naming the fix, for what a dataset of another robot cannot give."""
    if not env.imagined:
        raise ValueError(f"{data} was recorded on another robot, of which gymnast has no simulator: only "
                         "--env imagined can practise from its scenes")
    if config.real_eval or config.watch_every:
        raise ValueError(f"{data} was recorded on another robot, which gymnast cannot run: add --no-real-eval "
                         "--watch-every 0 (the real evaluation and the reward-hacking watch act in the real world)")
    if config.fresh_scenes or config.scenes is not None:
        raise ValueError(f"{data} was recorded on another robot: only its own scenes can start a rollout, "
                         "not --fresh-scenes or --scenes")
