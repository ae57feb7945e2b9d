"""Measure what a sim-to-real gap level does: expert success and open-loop divergence.

For each (task, seed) the scripted expert runs closed-loop in the real world and, separately, in
the gapped simulator (its success drop says how much harder the simulator is for a controller
that sees the true state). Then the real episode's actions are replayed open-loop in the gapped
simulator from the same seed, and the hand and object trajectories are compared step by step:
how far the same commands drift when the physics differ. Every episode is played by the rollout
engine (`gymnast.envs.engine.play_episode`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.envs.engine import Actor, EpisodeRun, ReplayActor, ScriptedActor, play_episode
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.gap import get_gap
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.parallel import cached_env, parallel_map
from gymnast.utils.atomic import write_bytes, write_json

_HAND = slice(0, 3)
_OBJECT = slice(4, 7)  # the first object's position in Meta-World's state vector


@dataclass(frozen=True)
class GapJob:
    task: str
    seed: int
    gap: str
    config: EnvConfig


def _play(env: MetaWorldEnv, seed: int, actor: Actor) -> EpisodeRun:
    return play_episode(env, actor, seed, record=("frames", "env_states"))


def measure_one(job: GapJob) -> dict:
    """Figures for one (task, seed) under one gap level."""
    # Replays must run the full recorded length, so the episodes here never stop on success.
    config = dataclasses.replace(job.config, terminate_on_success=False)
    real_env = cached_env(job.task, config)
    sim_env = cached_env(job.task, config, gap=job.gap)
    real = _play(real_env, job.seed, ScriptedActor(ScriptedExpert(job.task)))
    sim = _play(sim_env, job.seed, ScriptedActor(ScriptedExpert(job.task)))
    replay = _play(sim_env, job.seed, ReplayActor(np.array(real.actions)))
    real_states, replay_states = np.array(real.env_states), np.array(replay.env_states)  # (T + 1, E)
    hand_gap = np.linalg.norm(real_states[:, _HAND] - replay_states[:, _HAND], axis=1)
    object_gap = np.linalg.norm(real_states[:, _OBJECT] - replay_states[:, _OBJECT], axis=1)
    return {
        "task": job.task,
        "seed": job.seed,
        "real_expert_success": real.success,
        "sim_expert_success": sim.success,
        "replay_success": replay.success,
        "hand_divergence_cm_mean": float(100 * hand_gap.mean()),
        "hand_divergence_cm_final": float(100 * hand_gap[-1]),
        "object_divergence_cm_final": float(100 * object_gap[-1]),
        "first_frame_pixel_diff": float(np.abs(real.frames[0].astype(np.float32) - sim.frames[0]).mean() / 255.0),
    }


def measure_gap(
    gap: str, tasks: tuple[str, ...], episodes: int, config: EnvConfig, workers: int, first_seed: int,
    runner: str = "local",
) -> Iterator[dict]:
    """Yields `measure_one` results for every task and seed (in completion order), run in `workers`
    processes on `runner` (`gymnast.envs.workers.parse_runner`)."""
    jobs = [GapJob(task, first_seed + i, gap, config) for task in tasks for i in range(episodes)]
    yield from parallel_map(measure_one, jobs, workers, runner)


def measure_gap_levels(tasks: tuple[str, ...], episodes: int, levels: tuple[str, ...], config: EnvConfig, workers: int,
                       first_seed: int, progress: bool = True, runner: str = "local") -> dict:
    """Every level measured on `episodes` seeds per task: its settings, `summarise`'s figures and
    the per-episode records."""
    report = {"tasks": list(tasks), "episodes_per_task": episodes, "horizon": config.horizon, "levels": {}}
    for level in levels:
        records = list(tqdm(measure_gap(level, tasks, episodes, config, workers, first_seed, runner),
                            total=len(tasks) * episodes, desc=f"gap {level}", unit="ep", disable=not progress))
        report["levels"][level] = {"gap": dataclasses.asdict(get_gap(level)), **summarise(records), "records": records}
    return report


def format_level(level: str, overall: dict) -> str:
    """One line of a level's overall figures."""
    return (f"{level:>7}: expert success real {overall['real_expert_success']:.0%} -> sim "
            f"{overall['sim_expert_success']:.0%}; replayed real actions succeed "
            f"{overall['replay_success']:.0%}, hand drift {overall['hand_divergence_cm_final']:.1f} cm, "
            f"object drift {overall['object_divergence_cm_final']:.1f} cm")


def write_gap_report(out: Path, report: dict) -> Path:
    """`report` as JSON in `out` and as the markdown of `to_markdown` beside it (.md); returns the latter."""
    write_json(out, report)
    write_bytes(out.with_suffix(".md"), to_markdown(report).encode())
    return out.with_suffix(".md")


def summarise(records: list[dict]) -> dict:
    """Means over records: success rates and divergences, overall and per task."""

    def mean_of(rows: list[dict]) -> dict:
        keys = [k for k in rows[0] if k not in ("task", "seed")]
        return {k: float(np.mean([r[k] for r in rows])) for k in keys} | {"episodes": len(rows)}

    tasks = sorted({r["task"] for r in records})
    return {
        "overall": mean_of(records),
        "per_task": {t: mean_of([r for r in records if r["task"] == t]) for t in tasks},
    }


def to_markdown(report: dict) -> str:
    """The report as the tables of docs/sim_gap.md."""
    lines = [
        "# What the sim-to-real gap levels do (measured)",
        "",
        f"Made by `gymnast gap-report --tasks {','.join(report['tasks'])} --episodes "
        f"{report['episodes_per_task']}` ({report['episodes_per_task']} data seeds per task, horizon "
        f"{report['horizon']}; the JSON beside this file has every episode).",
        "",
        "- *expert success*: Meta-World's scripted expert, closed-loop on the true state, in each world.",
        "- *replay success*: the real expert episode's actions replayed open-loop in the simulator.",
        "- *hand / object drift*: distance between the real and the replayed trajectory at the last step.",
        "- *pixel diff*: mean absolute difference of the first frames, as a fraction of 255.",
        "",
        "| level | expert success real | expert success sim | replay success | hand drift (cm) | object drift (cm) | pixel diff |",
        "|---|---|---|---|---|---|---|",
    ]
    for level, result in report["levels"].items():
        o = result["overall"]
        lines.append(
            f"| {level} | {o['real_expert_success']:.0%} | {o['sim_expert_success']:.0%} | {o['replay_success']:.0%} "
            f"| {o['hand_divergence_cm_final']:.1f} | {o['object_divergence_cm_final']:.1f} | {o['first_frame_pixel_diff']:.3f} |"
        )
    for level, result in report["levels"].items():
        lines += ["", f"## {level}, per task", "",
                  "| task | expert success sim | replay success | hand drift (cm) | object drift (cm) |", "|---|---|---|---|---|"]
        for task, p in result["per_task"].items():
            lines.append(
                f"| {task} | {p['sim_expert_success']:.0%} | {p['replay_success']:.0%} "
                f"| {p['hand_divergence_cm_final']:.1f} | {p['object_divergence_cm_final']:.1f} |"
            )
    return "\n".join(lines) + "\n"
