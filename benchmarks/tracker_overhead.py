"""What logging to trackers costs an RL step: the same debug-size steps with --tracker none and
with tensorboard and wandb (offline), in one process, taking turns.

Each setting runs `gymnast rl` (`gymnast.rl.train.train_rl`) with the debug preset's step (4
rollouts of 10 actions in the simulator, the dense reward, a rollout video every step) for
`--steps` steps, `--rounds` times, alternating. Two figures: the time spent inside the trackers'
calls, timed around every call and summed by the step it logs (their start and close apart, once
a run), which is what they add to a step: the median over steps, and the mean, which holds the
one-off costs of a run's first video and metrics (W&B's media imports); and the steps' own
`time/step_s` in both settings, whose difference is that plus the machine's noise. W&B runs
offline in a temporary folder: nothing reaches the network.

    .venv/bin/python benchmarks/tracker_overhead.py [--steps 6] [--rounds 2]

Needs the wandb extra (`pip install 'world-gymnast[wandb]'`) and the committed SFT policy
(results/sft/policy). Prints and writes benchmarks/results/tracker_overhead.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.envs.kinds import env_kind
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RL_PRESETS, RLRun
from gymnast.rl.train import train_rl
from gymnast.utils import trackers
from gymnast.utils.atomic import write_json
from gymnast.utils.metrics import read_metrics

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "tracker_overhead.json"
POLICY = ROOT / "results/sft/policy"
SETTINGS = {"none": (), "tensorboard+wandb": ("tensorboard", "wandb")}
CALLS = ("log_config", "log_metrics", "log_video", "log_image")


class CallTimer:
    """Seconds spent in the fan-out's logging calls (opening and closing the trackers apart)."""

    def __init__(self) -> None:
        self.seconds = {name: 0.0 for name in CALLS}
        self.by_step: dict[int, float] = {}  # the logging calls' seconds by the step they log
        self.originals = {name: getattr(trackers.Trackers, name) for name in CALLS}

    def __enter__(self) -> CallTimer:
        for name, original in self.originals.items():
            setattr(trackers.Trackers, name, self._timed(name, original))
        return self

    def __exit__(self, *exc: object) -> None:
        for name, original in self.originals.items():
            setattr(trackers.Trackers, name, original)

    def _timed(self, name, original):
        def call(tracker, *args, **kwargs):
            began = time.perf_counter()
            try:
                return original(tracker, *args, **kwargs)
            finally:
                spent = time.perf_counter() - began
                self.seconds[name] += spent
                if name != "log_config":  # log_metrics(step, ...), log_video(key, step, ...), log_image(key, step, ...)
                    step = args[0] if name == "log_metrics" else args[1]
                    self.by_step[step] = self.by_step.get(step, 0.0) + spent
        return call


def run_once(names: tuple[str, ...], steps: int) -> dict:
    """`steps` debug RL steps logging to `names`; the steps' times (the first, warming up, left out)
    and the seconds inside the trackers' calls."""
    config = dataclasses.replace(RL_PRESETS["debug"], steps=steps, tracker=names, watch_every=0, eval_every=0,
                                 real_eval=False, checkpoint_every=10**6, fresh_scenes=True)
    with tempfile.TemporaryDirectory() as out, CallTimer() as timer:
        began = time.perf_counter()
        train_rl(RLRun(str(POLICY), env_kind("sim"), RewardSpec.parse("sim-dense")), Path(out), config, progress=False)
        wall = time.perf_counter() - began
        step_s = [m["time/step_s"] for m in read_metrics(Path(out)) if "time/step_s" in m][1:]
    return {"step_s": step_s, "wall_s": wall, "tracker_call_s": dict(timer.seconds),
            "tracker_step_s": [timer.by_step.get(step, 0.0) for step in range(1, steps + 1)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=6, help="RL steps per run (the first is not timed)")
    parser.add_argument("--rounds", type=int, default=2, help="runs of each setting, taking turns")
    args = parser.parse_args()
    trackers.require_trackers(["wandb"])
    folder = tempfile.mkdtemp(prefix="tracker-overhead-wandb-")
    os.environ.update({"WANDB_MODE": "offline", "WANDB_SILENT": "true", "WANDB_CONSOLE": "off", "WANDB_DIR": folder,
                       "WANDB_CONFIG_DIR": folder, "WANDB_CACHE_DIR": folder, "WANDB_DATA_DIR": folder})
    runs = {name: [] for name in SETTINGS}
    for _ in range(args.rounds):
        for name, names in SETTINGS.items():
            runs[name].append(run_once(names, args.steps))
    figures = {}
    for name, done in runs.items():
        steps = [s for run in done for s in run["step_s"]]
        per_step = [s for run in done for s in run["tracker_step_s"]]  # every step logs, the first too
        figures[name] = {"step_s_median": statistics.median(steps), "step_s_mean": statistics.mean(steps),
                         "steps_timed": len(steps), "tracker_s_per_step_median": statistics.median(per_step),
                         "tracker_s_per_step_mean": statistics.mean(per_step),
                         "tracker_calls_s_by_kind": {kind: sum(run["tracker_call_s"][kind] for run in done)
                                                     for kind in CALLS},
                         "wall_s_per_run": [round(run["wall_s"], 2) for run in done]}
    base, tracked = figures["none"], figures["tensorboard+wandb"]
    result = {
        "settings": {"preset": "debug", "env": "sim", "reward": "sim-dense", "steps": args.steps,
                     "rounds": args.rounds, "rollouts_per_step": RL_PRESETS["debug"].starts_per_step *
                     RL_PRESETS["debug"].group_size, "video_every": RL_PRESETS["debug"].video_every},
        "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()},
        "runs": figures,
        # What the trackers' calls add to a step, against the step without trackers: the median
        # step, and the mean with a run's one-off costs spread over its steps.
        "overhead_pct_calls_median": 100 * tracked["tracker_s_per_step_median"] / base["step_s_median"],
        "overhead_pct_calls_mean": 100 * tracked["tracker_s_per_step_mean"] / base["step_s_median"],
        # The steps' own difference (that, plus the machine's noise).
        "overhead_pct_step_median": 100 * (tracked["step_s_median"] / base["step_s_median"] - 1),
    }
    print(f"step (median) without trackers {base['step_s_median']:.3f} s, with tensorboard+wandb "
          f"{tracked['step_s_median']:.3f} s ({result['overhead_pct_step_median']:+.1f}%); inside the trackers' "
          f"calls {tracked['tracker_s_per_step_median'] * 1000:.1f} ms a step (median) = "
          f"{result['overhead_pct_calls_median']:.2f}% of a step, {tracked['tracker_s_per_step_mean'] * 1000:.1f} ms "
          f"(mean, with a run's one-off costs) = {result['overhead_pct_calls_mean']:.2f}%")
    write_json(RESULTS, result)
    print(f"-> {RESULTS}")


if __name__ == "__main__":
    main()
