"""What keeping large blocks in the heap buys (`gymnast.utils.memory.reuse_large_blocks`): time, page
faults and peak memory, with glibc's own behaviour (``GYMNAST_HEAP_REUSE=off``) as the reference.

Two workloads, each setting in its own process, the two settings alternating for `--rounds` rounds
(medians), so that a busy machine slows both alike:

- ``imagine``: a world model imagines `--chunks` chunks of `--batch` rollouts (three cameras with the
  default, the three-camera headline's model), in this script's process: frames per second, the
  page faults and the CPU time spent in the kernel;
- ``rl``: one step of `gymnast rl` in the real world with the three-camera SFT policy (the command
  of benchmarks/rl_update_memory.py), as a user runs it: wall time, update time and peak resident
  memory (sampled every 0.2 s).

    .venv/bin/python benchmarks/heap_reuse.py --data runs/headline_three/data

Prints and writes --out (default benchmarks/results/heap_reuse.json).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rl_update_memory import ROOT, sampled_run

from gymnast.utils.atomic import write_json
from gymnast.utils.memory import HEAP_REUSE_VARIABLE
from gymnast.utils.metrics import read_metrics

SETTINGS = ("off", "auto")


def imagine_child(wm: Path, batch: int, chunks: int) -> dict:
    """In a fresh process: the heap set up as the `gymnast` command sets it, then the imagination timed."""
    import torch
    from world_model import imagined_fps

    from gymnast.utils.memory import reuse_large_blocks
    from gymnast.world_model.base import load_world_model

    reused = reuse_large_blocks()
    model = load_world_model(wm).eval()
    with torch.no_grad():
        imagined_fps(model, batch, 5, 2)  # warm-up: kernels picked, the heap grown
        before = resource.getrusage(resource.RUSAGE_SELF)
        fps, peak_mib = imagined_fps(model, batch, 5, chunks)
        after = resource.getrusage(resource.RUSAGE_SELF)
    return {"reused": reused, "frames_per_s": fps, "page_faults": after.ru_minflt - before.ru_minflt,
            "kernel_cpu_s": after.ru_stime - before.ru_stime, "user_cpu_s": after.ru_utime - before.ru_utime,
            "peak_rss_mib": peak_mib}


def imagine(setting: str, args: argparse.Namespace) -> dict:
    command = [sys.executable, __file__, "--child", "--wm", str(args.wm), "--batch", str(args.batch),
               "--chunks", str(args.chunks)]
    done = subprocess.run(command, env={**os.environ, HEAP_REUSE_VARIABLE: setting}, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def rl_step(setting: str, args: argparse.Namespace) -> dict:
    with tempfile.TemporaryDirectory() as out:
        command = [str(Path(sys.executable).with_name("gymnast")), "rl", "--env", "real", "--reward", "sim",
                   "--preset", "demo", "--policy", str(args.policy), "--data", str(args.data), "--tasks", args.tasks,
                   "--steps", "1", "--starts-per-step", "5", "--group-size", "8", "--workers", "1",
                   "--eval-every", "0", "--no-real-eval", "--watch-every", "0", "--video-every", "1000",
                   "--checkpoint-every", "1000", "--out", str(Path(out) / "rl")]
        began = time.perf_counter()
        figures = sampled_run(command, env={**os.environ, HEAP_REUSE_VARIABLE: setting})
        step = next(m for m in read_metrics(Path(out) / "rl") if "time/update_s" in m)
    return {**figures, "wall_s": time.perf_counter() - began, "update_s": step["time/update_s"],
            "rollout_s": step["time/rollout_s"], "reward_mean": step.get("reward/mean")}


def medians(rows: list[dict]) -> dict:
    return {key: statistics.median(row[key] for row in rows) for key in rows[0] if isinstance(rows[0][key], float | int)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wm", type=Path, default=ROOT / "results/headline_three/world_model")
    parser.add_argument("--policy", type=Path, default=ROOT / "results/sft/three/policy")
    parser.add_argument("--data", type=Path, help="a dataset of the policy's cameras (the rl workload's starts)")
    parser.add_argument("--tasks", default="reach-v3,push-v3")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--chunks", type=int, default=12)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workloads", nargs="+", default=["imagine", "rl"], choices=["imagine", "rl"])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/heap_reuse.json"))
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(imagine_child(args.wm, args.batch, args.chunks)))
        return
    if "rl" in args.workloads and args.data is None:
        parser.error("the rl workload needs --data")
    workloads = {"imagine": imagine, "rl": rl_step}
    report = {}
    for name in args.workloads:
        runs = {setting: [] for setting in SETTINGS}
        for _ in range(args.rounds):
            for setting in SETTINGS:
                runs[setting].append(workloads[name](setting, args))
        report[name] = {setting: {"median": medians(rows), "runs": rows} for setting, rows in runs.items()}
        for setting in SETTINGS:
            print(f"{name} {HEAP_REUSE_VARIABLE}={setting}: " +
                  ", ".join(f"{key} {value:.3g}" for key, value in report[name][setting]["median"].items()))
    write_json(args.out, {**report, "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
                          "command": " ".join(["benchmarks/heap_reuse.py", *sys.argv[1:]])})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
