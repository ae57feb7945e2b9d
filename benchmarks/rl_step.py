"""Wall time of one RL step, split into rollout (world model or simulator), policy, reward and update.

Runs the real `gymnast rl` loop (`gymnast.rl.train.train_rl`) for a few steps in each setting and
takes the medians of the per-step timings it logs. One step is one round of B x G rollouts of the
full horizon (dynamic sampling is off here, so a step never repeats its round) and one policy
update. The real-world setting runs in the same process, right after, as the reference the
imagined settings are compared with on this (shared, noisy) machine.

    .venv/bin/python benchmarks/rl_step.py [--data data/mt10] [--steps 4]

Needs the committed policy, world model and judge (results/) and a dataset of their image size
(96 px; `gymnast collect --tasks mt10 ...`). Prints and writes benchmarks/results/rl_step.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import resource
import statistics
import tempfile
from pathlib import Path

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.envs.kinds import env_kind
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RL_PRESETS, RLRun
from gymnast.rl.train import train_rl
from gymnast.utils.atomic import write_json
from gymnast.utils.metrics import read_metrics

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "rl_step.json"
POLICY, WORLD_MODEL, JUDGE = ROOT / "results/sft/policy", ROOT / "results/world_model/wm", ROOT / "results/judge/video_judge"
SETTINGS = {
    "imagined_judge": ("imagined", f"judge:{JUDGE}"),
    "imagined_verified": ("imagined", "verified"),
    "real_sim": ("real", "sim"),
}


def time_setting(env: str, reward: str, data: Path, steps: int, tasks: str, policy: Path = POLICY,
                 wm: Path = WORLD_MODEL, **overrides) -> dict:
    """Median timings of `steps` RL steps (the first not timed) of the full preset, with `overrides`
    of its settings (e.g. starts_per_step, device)."""
    config = dataclasses.replace(
        RL_PRESETS["full"], steps=steps, tasks=tasks, max_rounds=1, keep_low=0.0, keep_high=1.0, eval_episodes=1,
        real_eval=False, watch_every=0, video_every=10**6, checkpoint_every=10**6, tracker=(), **overrides,
    )
    with tempfile.TemporaryDirectory() as out:
        run = RLRun(str(policy), env_kind(env), RewardSpec.parse(reward), str(wm), str(data))
        train_rl(run, Path(out), config, progress=False)
        lines = [m for m in read_metrics(Path(out)) if "time/step_s" in m][1:]  # the first step warms up
    median = {key: statistics.median(m[f"time/{key}"] for m in lines)
              for key in ("step_s", "rollout_s", "policy_s", "reward_s", "update_s")}
    return {
        "rollouts_per_step": config.starts_per_step * config.group_size,
        "horizon": config.horizon,
        "steps_timed": len(lines),
        "step_s": median["step_s"],
        # collect_rollouts times the policy's sampling inside the rollout; the rest is the env.
        "env_s": median["rollout_s"] - median["policy_s"],
        "policy_s": median["policy_s"],
        "reward_s": median["reward_s"],
        "update_s": median["update_s"],
        "policy_calls": statistics.median(m.get("train/policy_calls", 0) for m in lines),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT / "data/mt10", help="dataset of start states (96 px)")
    parser.add_argument("--steps", type=int, default=4, help="RL steps per setting (the first is not timed)")
    parser.add_argument("--tasks", default="reach-v3,push-v3,drawer-open-v3,window-open-v3")
    args = parser.parse_args()
    results = {name: time_setting(env, reward, args.data, args.steps, args.tasks) for name, (env, reward) in SETTINGS.items()}
    for name, figures in results.items():
        print(f"{name:18s} step {figures['step_s']:6.1f} s = env {figures['env_s']:5.1f} + policy {figures['policy_s']:4.1f}"
              f" + reward {figures['reward_s']:4.1f} + update {figures['update_s']:4.1f}  ({figures['rollouts_per_step']}"
              f" rollouts x {figures['horizon']} actions)")
    report = {
        "settings": results,
        "imagined_judge_speedup_over_real": results["real_sim"]["step_s"] / results["imagined_judge"]["step_s"],
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
        "command": "benchmarks/rl_step.py " + f"--data {args.data} --steps {args.steps} --tasks {args.tasks}",
    }
    write_json(RESULTS, report)
    print(f"imagined (judge) step is {report['imagined_judge_speedup_over_real']:.1f}x faster than a real-world step; "
          f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
