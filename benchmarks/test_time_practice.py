"""Test-time practice: given one new scene's first frame and its instruction, practise in
imagination, then act in the real world; does the policy do better on that scene than before?

For each scene (the first evaluation seeds of each task: scenes that are in no dataset), one
`gymnast rl --env imagined --scenes TASK:SEED` run from the SFT policy: every rollout starts from
the scene's real first frame, rendered by a reset (no action is taken), and is judged on its
imagined video. The run evaluates the greedy policy on that scene before and after, in
imagination and in the real world, and the reward-hacking watch replays some of the last step's
imagined rollouts in the real world.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/test_time_practice.py [--scenes-per-task 5] [--steps 8]

Reruns skip the scenes already practised (RUN/summary.json exists); ``--report-only`` tabulates.
Writes runs/practice/<task>_<seed>/ (one RL run each) and results/rl/practice/ (practice.json,
practice.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gymnast.envs.kinds import env_kind
from gymnast.envs.tasks import eval_seed, resolve_tasks
from gymnast.eval.stats import wilson_interval
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RLConfig, RLRun
from gymnast.rl.train import train_rl
from gymnast.utils.atomic import write_json
from gymnast.utils.metrics import read_metrics

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl" / "practice"
WEAK_TASKS = "reach-v3,push-v3,pick-place-v3,peg-insert-side-v3"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="results/sft/policy")
    parser.add_argument("--wm", default="results/world_model/wm")
    parser.add_argument("--reward", default="judge:results/judge/judge")
    parser.add_argument("--tasks", default=WEAK_TASKS)
    parser.add_argument("--scenes-per-task", type=int, default=5)
    parser.add_argument("--steps", type=int, default=8)
    parser.add_argument("--starts-per-step", type=int, default=4, help="groups a step (all from the one scene)")
    parser.add_argument("--group-size", type=int, default=8)
    parser.add_argument("--lr", type=float, default=3e-5)
    parser.add_argument("--watch-rollouts", type=int, default=16, help="imagined rollouts replayed after the last step")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "practice")
    parser.add_argument("--report-only", action="store_true", help="only tabulate the scenes already practised")
    args = parser.parse_args()
    scenes = [(task, eval_seed(i)) for task in resolve_tasks(args.tasks) for i in range(args.scenes_per_task)]
    run_spec = RLRun(policy=args.policy, env=env_kind("imagined"), reward=RewardSpec.parse(args.reward), wm=args.wm)
    settings = RLConfig(steps=args.steps, starts_per_step=args.starts_per_step, group_size=args.group_size, lr=args.lr,
                        warmup_steps=1, eval_every=0, watch_every=args.steps, watch_rollouts=args.watch_rollouts,
                        video_every=args.steps, checkpoint_every=args.steps, workers=1, tensorboard=False)
    for k, (task, seed) in enumerate(scenes):
        out = args.out / f"{task}_{seed}"
        if args.report_only or (out / "summary.json").exists():
            continue
        print(f"[{k + 1}/{len(scenes)}] practising on {task}:{seed}", flush=True)
        train_rl(run_spec, out, RLConfig(**vars(settings) | {"scenes": f"{task}:{seed}"}), progress=False)
    rows = [measure(task, seed, args.out / f"{task}_{seed}") for task, seed in scenes
            if (args.out / f"{task}_{seed}" / "summary.json").exists()]
    results = {"command": " ".join(sys.argv), "settings": {"run": run_spec.to_json(), "rl": vars(settings)},
               "scenes": rows, "totals": totals(rows)}
    write_json(RESULTS / "practice.json", results)
    (RESULTS / "practice.md").write_text(table(results))
    print(table(results))


def measure(task: str, seed: int, run: Path) -> dict:
    """One scene's greedy success before and after practice, in imagination and in the real world,
    and what the watch saw on the last step's imagined rollouts."""
    import json

    summary = json.loads((run / "summary.json").read_text())
    metrics = read_metrics(run)
    watched = [m for m in metrics if "eval/watch_real_success" in m]
    last = watched[-1] if watched else {}
    steps = [m for m in metrics if "rollout/kept_groups" in m]
    return {"task": task, "seed": seed,
            # A step updates the policy only where the judge's verdicts on the scene's rollouts differ.
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
    for key in ("reset_frames", "real_interactions", "watch_real_interactions", "wall_s"):
        out[key] = sum(row[key] for row in rows)
    return out


def table(results: dict) -> str:
    rows, t = results["scenes"], results["totals"]

    def rate(key: str) -> str:
        value = t[key]
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
    lines += ["", f"Over {t['scenes']} scenes: real success {rate('real_before')} before, {rate('real_after')} after "
              f"({t['gained']} scenes gained, {t['lost']} lost); judged in imagination {rate('imagined_before')} -> "
              f"{rate('imagined_after')}. First frames rendered by a reset: {t['reset_frames']}; real interactions "
              f"in training: {t['real_interactions']}; spent by the watch: {t['watch_real_interactions']}; "
              f"{t['wall_s'] / 60:.0f} minutes.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
