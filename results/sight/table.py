"""The sight gap of each measured policy (results/sight/measure.sh): on the same 20 scenes per MT10
task, its greedy episodes in the real world against its greedy plans made on the world model's
frames and executed for real. Writes results/sight/summary.json and prints the table.

    .venv/bin/python results/sight/table.py sft imagined control
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

from gymnast.data.lerobot import EpisodeDataset
from gymnast.eval.stats import wilson_interval

RUNS, RESULTS = Path("runs/sight"), Path("results/sight")


def outcomes(dataset: Path) -> dict[tuple[str, int], bool]:
    return {(info.task, info.seed): bool(info.success) for info in EpisodeDataset(dataset).episodes}


def rate(successes: int, episodes: int) -> dict:
    low, high = wilson_interval(successes, episodes)
    return {"success": successes / episodes, "ci_low": low, "ci_high": high, "successes": successes, "episodes": episodes}


def measured(name: str) -> dict:
    real, planned = outcomes(RUNS / name / "real"), outcomes(RUNS / name / "planned")
    scenes = sorted(set(real) & set(planned))
    per_task = {}
    for task in sorted({task for task, _ in scenes}):
        mine = [scene for scene in scenes if scene[0] == task]
        per_task[task] = {"real": sum(real[s] for s in mine), "planned": sum(planned[s] for s in mine), "scenes": len(mine)}
    pairs = Counter((real[s], planned[s]) for s in scenes)
    evaluation = json.loads((RUNS / name / "eval.json").read_text())
    return {"real": rate(sum(real[s] for s in scenes), len(scenes)),
            "planned": rate(sum(planned[s] for s in scenes), len(scenes)),
            "only_real": pairs[(True, False)], "only_planned": pairs[(False, True)], "per_task": per_task,
            "eval": {key: evaluation[key] for key in ("success", "ci_low", "ci_high", "episodes")}}


def main(names: list[str]) -> None:
    summary = {name: measured(name) for name in names}
    (RESULTS / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    for name, row in summary.items():
        real, planned, evaluation = row["real"], row["planned"], row["eval"]
        print(f"| {name} | {real['success']:.1%} [{real['ci_low']:.1%}, {real['ci_high']:.1%}] | "
              f"{planned['success']:.1%} [{planned['ci_low']:.1%}, {planned['ci_high']:.1%}] | "
              f"{row['only_real']} / {row['only_planned']} | "
              f"{evaluation['success']:.1%} [{evaluation['ci_low']:.1%}, {evaluation['ci_high']:.1%}] |")


if __name__ == "__main__":
    main(sys.argv[1:])
