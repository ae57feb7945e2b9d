"""Evaluation episodes per second of policies that see different cameras: `gymnast eval` as a user runs it.

Each policy is evaluated on the same tasks and evaluation seeds (greedy, no videos) in its own
`gymnast eval` process, worker start-up included; the policies take turns for a few rounds, so
that load from other processes hits them alike, and each keeps its fastest round. Each renders the
views it was trained on (one frame per chunk of actions: the frames it reads), so the figure is
the cost of a view in the evaluation loop, policy included. Episodes end at success, so a better
policy also finishes sooner: its success is reported beside.

    .venv/bin/python benchmarks/eval_cameras.py front=results/sft/policy \\
        front+gripper=results/sft/cameras/policy front+gripper+hand=results/sft/three/policy \\
        [--tasks mt10] [--episodes 5] [--workers 2] [--rounds 2] [--out JSON]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from gymnast.utils.atomic import read_json, write_json

RESULTS = Path(__file__).parent / "results" / "eval_cameras.json"


def timed_eval(policy: Path, tasks: str, episodes: int, workers: int) -> tuple[float, dict]:
    """Seconds one `gymnast eval` took, and its report."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "eval.json"
        command = [sys.executable, "-m", "gymnast.cli", "eval", "--policy", str(policy), "--out", str(out),
                   "--tasks", tasks, "--episodes", str(episodes), "--workers", str(workers), "--videos-per-task", "0"]
        began = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return time.perf_counter() - began, read_json(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="NAME=RUN: a policy run and what to call it")
    parser.add_argument("--tasks", default="mt10")
    parser.add_argument("--episodes", type=int, default=5, help="per task")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    policies = dict(item.split("=", 1) for item in args.policies)
    seconds: dict[str, list[float]] = {name: [] for name in policies}
    reports: dict[str, dict] = {}
    for _ in range(args.rounds):
        for name, run in policies.items():
            took, reports[name] = timed_eval(Path(run), args.tasks, args.episodes, args.workers)
            seconds[name].append(round(took, 2))
    episodes = reports[next(iter(policies))]["episodes"]
    result = {"setups": {name: {"policy": run, "seconds": min(seconds[name]), "rounds_s": seconds[name],
                                "episodes_per_s": round(episodes / min(seconds[name]), 3),
                                "success": reports[name]["success"]} for name, run in policies.items()},
              "tasks": args.tasks, "episodes": episodes, "workers": args.workers,
              "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()}}
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
