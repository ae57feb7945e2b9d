"""Peak resident memory and update time of one real-world RL step, by the update's micro-batch.

The policy update runs its forward and backward passes over `--micro-batch` policy calls at a
time (gradients accumulate, so the result does not depend on it): the activations kept for the
backward pass grow with it, and with every camera the policy sees. Each setting runs the same
`gymnast rl` step (the same seed, so the same rollouts and the same update) in its own process,
whose resident memory, and that of its simulator processes, is sampled every 0.2 s.

    .venv/bin/python benchmarks/rl_update_memory.py --policy results/sft/three/policy \\
        --data runs/headline_three/data --micro-batches 256 64 16 \\
        --out benchmarks/results/rl_update_memory_three.json

Prints and writes --out (default benchmarks/results/rl_update_memory.json).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

from gymnast.utils.atomic import write_json
from gymnast.utils.metrics import read_metrics

ROOT = Path(__file__).resolve().parents[1]


def sampled_run(command: list[str], every_s: float = 0.2, env: dict[str, str] | None = None) -> dict:
    """Runs `command` (in `env`, default this process's), sampling the resident memory of its
    process and of the whole process tree."""
    with tempfile.TemporaryFile("w+") as log:  # a file, not a pipe nobody reads while it runs
        process = psutil.Popen(command, stdout=subprocess.DEVNULL, stderr=log, env=env)
        peak_main = peak_tree = 0
        while process.poll() is None:
            try:
                main = process.memory_info().rss
                children = sum(child.memory_info().rss for child in process.children(recursive=True))
            except psutil.Error:  # it or a child ended between the calls
                continue
            peak_main, peak_tree = max(peak_main, main), max(peak_tree, main + children)
            time.sleep(every_s)
        if process.returncode:
            log.seek(0)
            raise RuntimeError(f"{' '.join(command)} failed ({process.returncode}):\n{log.read()[-3000:]}")
    return {"peak_rss_gib": peak_main / 2**30, "peak_tree_rss_gib": peak_tree / 2**30}


def measure(micro_batch: int, args: argparse.Namespace) -> dict:
    with tempfile.TemporaryDirectory() as out:
        command = [str(Path(sys.executable).with_name("gymnast")), "rl", "--env", "real", "--reward", "sim", "--preset", "demo",
                   "--policy", str(args.policy), "--data", str(args.data), "--tasks", args.tasks, "--steps", "1",
                   "--starts-per-step", str(args.starts_per_step), "--group-size", "8", "--workers", "1",
                   "--micro-batch", str(micro_batch), "--eval-every", "0", "--no-real-eval", "--watch-every", "0",
                   "--video-every", "1000", "--checkpoint-every", "1000", "--out", str(Path(out) / "rl")]
        began = time.perf_counter()
        figures = sampled_run(command)
        step = next(m for m in read_metrics(Path(out) / "rl") if "time/update_s" in m)
    return {"micro_batch": micro_batch, **figures, "wall_s": time.perf_counter() - began,
            "update_s": step["time/update_s"], "rollout_s": step["time/rollout_s"],
            "policy_calls": step.get("train/policy_calls"), "rounds": step.get("rollout/rounds"),
            "reward_mean": step.get("reward/mean")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, default=ROOT / "results/sft/three/policy")
    parser.add_argument("--data", type=Path, required=True, help="a dataset of the policy's cameras (start states)")
    parser.add_argument("--tasks", default="reach-v3,push-v3")
    parser.add_argument("--starts-per-step", type=int, default=5, help="GRPO groups of 8 rollouts")
    parser.add_argument("--micro-batches", type=int, nargs="+", default=[256, 64, 16])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/rl_update_memory.json"))
    args = parser.parse_args()
    rows = []
    for micro_batch in args.micro_batches:
        rows.append(measure(micro_batch, args))
        row = rows[-1]
        print(f"micro-batch {micro_batch:4d}: peak {row['peak_rss_gib']:.2f} GiB (with its simulator process "
              f"{row['peak_tree_rss_gib']:.2f}), update {row['update_s']:.1f} s of {row['policy_calls']:.0f} calls, "
              f"reward {row['reward_mean']:.4f}")
    write_json(args.out, {"rows": rows, "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
                          "command": " ".join(["benchmarks/rl_update_memory.py", *sys.argv[1:]])})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
