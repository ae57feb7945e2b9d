"""results/practice/summary.json: practice in imagination against SFT and RL in the real world, from
the runs that measured them.

Every arm is read from an RL run's summary.json (`gymnast rl`), whose evaluations in the real
world start at the evaluation seeds' first frames: SFT is a run's step-0 evaluation (the policy
before any update), an RL arm its last. Arms are grouped by task set (``weak``, ``mt10``):

    {"weak": {"sft": {"success", "ci_low", "ci_high", "episodes", "real_interactions"},
              "imagined_rl": {...}, "real_rl": {...}}, "mt10": {...}}

``real_interactions`` counts the real actions an arm's training took (the evaluations' are apart,
in ``eval_real_interactions``): 0 for SFT and for practice in imagination, whose reward-hacking
watch replays are counted in ``watch_real_interactions``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from gymnast.utils.atomic import read_json, write_json

ARMS = ("sft", "imagined_rl", "real_rl")


def arm_from_run(run: Path, at_start: bool = False) -> dict:
    """One arm's figures from an RL run: its last real-world evaluation (the first with `at_start`).

    Raises:
        FileNotFoundError: the run has no summary.json (it has not finished).
        ValueError: the run has no real-world evaluation.
    """
    path = Path(run) / "summary.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist: has the run finished?")
    summary = read_json(path)
    when = "start" if at_start else "end"
    success = summary.get(f"{when}_real_success")
    if success is None:
        raise ValueError(f"{path}: no evaluation in the real world ({when}_real_success)")
    low, high = summary[f"{when}_real_ci"]
    point = summary["curve"][0 if at_start else -1]
    # A run in the real world evaluates there as its own env; one elsewhere reports the real world apart.
    episodes = point.get("eval/real_episodes", point.get("eval/own_episodes"))
    return {"success": success, "ci_low": low, "ci_high": high, "episodes": episodes,
            "real_interactions": 0 if at_start else summary["real_interactions"],
            "eval_real_interactions": point.get("eval/real_interactions", 0),  # the evaluations' so far
            "watch_real_interactions": 0 if at_start else summary["watch_real_interactions"],
            "steps": 0 if at_start else summary["steps"], "env": None if at_start else summary["env"],
            "reward": None if at_start else summary["reward"], "run": str(run)}


def practice_summary(runs: Mapping[str, Mapping[str, Path]], out: Path) -> dict:
    """summary.json of `runs` ({task set: {"imagined_rl": RUN, "real_rl": RUN}}); SFT is read from
    the imagined run's step-0 evaluation. Written to `out`."""
    summary = {}
    for task_set, arms in runs.items():
        unknown = set(arms) - set(ARMS[1:])
        if unknown:
            raise ValueError(f"unknown arm {sorted(unknown)[0]!r} for {task_set}; the RL arms are {ARMS[1:]}")
        first = arms.get("imagined_rl") or next(iter(arms.values()))
        summary[task_set] = {"sft": arm_from_run(first, at_start=True)} | {
            arm: arm_from_run(run) for arm, run in arms.items()}
    write_json(out, summary)
    return summary
