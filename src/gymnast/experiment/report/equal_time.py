"""The RL arms at equal wall-clock, beside the equal steps the headline gives them.

Imagination is cheaper than rendering, so equal steps are not equal time: in the minutes a
world-model arm trained, RL in the real world got through fewer steps, and in the minutes RL in
the real world took, an imagined arm had time for more. Both are read from each run's own
``metrics.jsonl`` (``time/step_s``: the step's rollouts and update, without the evaluations and the
reward-hacking watch, which every arm runs alike), and the real arm's success at equal time from its
learning curve: its last evaluation by then.
"""

from __future__ import annotations

import json
from pathlib import Path

REFERENCE = "rl_real"
"""The arm the others are timed against: RL in the real world, the upper bound."""


def training_seconds(run: Path) -> list[float]:
    """Seconds of training up to the end of each step (entry i: steps 1..i+1), from the run's
    metrics.jsonl; a step logged twice (a resumed run repeats the steps after its last checkpoint)
    counts once, with its last time."""
    per_step: dict[int, float] = {}
    for line in (run / "metrics.jsonl").read_text().splitlines():
        values = json.loads(line)
        if "time/step_s" in values:
            per_step[values["step"]] = values["time/step_s"]
    elapsed, total = [], 0.0
    for step in sorted(per_step):
        total += per_step[step]
        elapsed.append(total)
    return elapsed


def equal_wall_clock(runs: dict[str, Path], reference_curve: list[dict]) -> dict | None:
    """Each arm's steps and training time against the reference's at the same time.

    Args:
        runs: arm name -> its RL run directory, the reference (`REFERENCE`) among them.
        reference_curve: the reference's learning curve (`{"step", "real", "real_ci"}` points).

    Returns:
        None without the reference run; else ``{"reference": {"arm", "steps", "train_s"}, "arms":
        {name: {"steps", "train_s", "reference_steps_in_that_time", "reference_at_that_time",
        "steps_in_reference_time"}}}``: the reference's success at its last evaluation by the arm's
        training time (None before its first), and how many of the arm's steps, at its mean step
        time, the reference's training time would have paid for (a projection, never run).
    """
    if REFERENCE not in runs:
        return None
    reference = training_seconds(runs[REFERENCE])
    if not reference:
        return None
    arms = {}
    for name, run in runs.items():
        elapsed = training_seconds(run)
        if name == REFERENCE or not elapsed:
            continue
        steps, seconds = len(elapsed), elapsed[-1]
        reached = sum(1 for done in reference if done <= seconds)
        evaluated = [point for point in reference_curve if point["step"] <= reached and point.get("real") is not None]
        at_time = evaluated[-1] if evaluated else None
        arms[name] = {
            "steps": steps,
            "train_s": seconds,
            "reference_steps_in_that_time": reached,
            "reference_at_that_time": None if at_time is None else {
                "step": at_time["step"], "success": at_time["real"], "ci_low": at_time["real_ci"][0],
                "ci_high": at_time["real_ci"][1]},
            "steps_in_reference_time": int(reference[-1] / (seconds / steps)),
        }
    return {"reference": {"arm": REFERENCE, "steps": len(reference), "train_s": reference[-1]}, "arms": arms}
