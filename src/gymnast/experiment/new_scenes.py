"""Test-time practice on new scenes: the policy is about to face a scene no dataset holds; does
practising on it in imagination first help it there in the real world?

World-Gymnast gives each task as one initial image and an instruction. For each scene (a task and
an evaluation seed: in no dataset), one `gymnast rl --env imagined --scenes TASK:SEED` run from the
policy: every rollout starts from the scene's real first frame, rendered by a reset (no action is
taken, counted in ``reset_frames``), and is scored on its imagined video. The run evaluates the
greedy policy on that scene before and after, in imagination and in the real world, and the
reward-hacking watch replays some of the last step's imagined rollouts in the real world. Those
real episodes measure; training takes no real interaction.

`benchmarks/test_time_practice.py` runs it on its own; the headline runs it as its ``new_scenes``
stage with the experiment's SFT policy, world model and judge.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from gymnast.eval.stats import wilson_interval
from gymnast.rl.config import RLConfig, RLRun
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import has_checkpoint

Scene = tuple[str, int]
"""A task and the data seed of its scene."""


def scenes_for(tasks: list[str], per_task: int) -> list[Scene]:
    """The first `per_task` evaluation seeds of each task: scenes that are in no dataset."""
    from gymnast.envs.tasks import eval_seed

    return [(task, eval_seed(i)) for task in tasks for i in range(per_task)]


def practice_settings(base: RLConfig, steps: int, starts_per_step: int) -> RLConfig:
    """`base`'s recipe (batch of `base.group_size`, learning rate, anchors) for `steps` steps of
    `starts_per_step` groups on one scene; the watch and a video after the last step; no
    evaluation between the first and the last (each is one greedy episode on the scene)."""
    return dataclasses.replace(base, steps=steps, starts_per_step=starts_per_step, fresh_scenes=False,
                               keyframes="first", warmup_steps=min(base.warmup_steps, 1), eval_every=0,
                               watch_every=steps, video_every=steps, checkpoint_every=steps, tracker=())


def practise(run_spec: RLRun, settings: RLConfig, scenes: list[Scene], out: Path, progress: bool = True) -> list[dict]:
    """Practises on each scene in its own run, ``out/<task>_<seed>`` (a scene whose run finished is
    not practised again: a rerun continues), and returns each scene's `measure` row."""
    from gymnast.rl.train import train_rl

    rows = []
    for task, seed in scenes:
        run = out / f"{task}_{seed}"
        if not (run / "summary.json").exists():
            train_rl(run_spec, run, dataclasses.replace(settings, scenes=f"{task}:{seed}"),
                     resume=has_checkpoint(run), progress=progress)
        rows.append(measure(task, seed, run))
    return rows


def measure(task: str, seed: int, run: Path) -> dict:
    """One scene's greedy success before and after practice, in imagination and in the real world,
    and what the watch saw on the last step's imagined rollouts."""
    from gymnast.utils.metrics import read_metrics

    summary = read_json(run / "summary.json")
    metrics = read_metrics(run)
    watched = [m for m in metrics if "eval/watch_real_success" in m]
    last = watched[-1] if watched else {}
    steps = [m for m in metrics if "rollout/kept_groups" in m]
    return {"task": task, "seed": seed,
            # A step updates the policy only where the verdicts on the scene's rollouts differ.
            "updates": sum(m["rollout/kept_groups"] > 0 for m in steps), "steps": len(steps),
            "judged_train_success": [m["rollout/success"] for m in steps],
            "imagined_before": summary["start_success"], "imagined_after": summary["end_success"],
            "real_before": summary["start_real_success"], "real_after": summary["end_real_success"],
            "watch_imagined_success": last.get("eval/watch_imagined_success"),
            "watch_real_success": last.get("eval/watch_real_success"),
            "watch_false_success": last.get("eval/watch_false_success"),
            "reset_frames": summary["reset_frames"], "real_interactions": summary["real_interactions"],
            "eval_real_interactions": summary["eval_real_interactions"],
            "watch_real_interactions": summary["watch_real_interactions"], "wall_s": summary["wall_s"]}


def totals(rows: list[dict]) -> dict:
    """Real and imagined success over all scenes before and after, with 95% Wilson intervals, and
    how many scenes practice turned from failure to success and back."""
    n = len(rows)
    out: dict = {"scenes": n}
    for key in ("real_before", "real_after", "imagined_before", "imagined_after"):
        wins = sum(bool(row[key]) for row in rows)
        out[key] = {"success": wins / n if n else None, "ci": list(wilson_interval(wins, n)) if n else None}
    out["gained"] = sum(not row["real_before"] and bool(row["real_after"]) for row in rows)
    out["lost"] = sum(bool(row["real_before"]) and not row["real_after"] for row in rows)
    for key in ("reset_frames", "real_interactions", "eval_real_interactions", "watch_real_interactions", "wall_s"):
        out[key] = sum(row[key] for row in rows)
    return out


def table(rows: list[dict], total: dict) -> list[str]:
    """Markdown lines: one row per scene, then a sentence over all of them (`total`: `totals`)."""

    def rate(key: str) -> str:
        value = total[key]
        return "n/a" if value["success"] is None else (
            f"{value['success']:.0%} [{value['ci'][0]:.0%}, {value['ci'][1]:.0%}]")

    def mark(value) -> str:
        return "n/a" if value is None else ("yes" if value else "no")

    lines = ["| task | seed | steps that updated | judged success of the training rollouts, per step | "
             "imagined before -> after | real before -> after | watch: judged / real success of the last step's "
             "rollouts |", "|---|---|---|---|---|---|---|"]
    for row in rows:
        watch = ("n/a" if row["watch_imagined_success"] is None else
                 f"{row['watch_imagined_success']:.0%} / {row['watch_real_success']:.0%}")
        judged = ", ".join(f"{x:.0%}" for x in row["judged_train_success"])
        lines.append(f"| {row['task']} | {row['seed']} | {row['updates']} of {row['steps']} | {judged} | "
                     f"{mark(row['imagined_before'])} -> {mark(row['imagined_after'])} "
                     f"| {mark(row['real_before'])} -> {mark(row['real_after'])} | {watch} |")
    lines += ["", f"Over {total['scenes']} scenes: real success {rate('real_before')} before, {rate('real_after')} "
              f"after ({total['gained']} scenes gained, {total['lost']} lost); judged in imagination "
              f"{rate('imagined_before')} -> {rate('imagined_after')}. First frames rendered by a reset: "
              f"{total['reset_frames']}; real interactions in training: {total['real_interactions']}; spent by the "
              f"evaluations and the watch: {total['eval_real_interactions'] + total['watch_real_interactions']}; "
              f"{total['wall_s'] / 60:.0f} minutes.", ""]
    return lines
