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
from gymnast.envs.tasks import resolve_tasks
from gymnast.experiment.new_scenes import practice_settings, practise, scenes_for, table, totals
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RLConfig, RLRun
from gymnast.utils.atomic import write_json

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl" / "practice"
WEAK_TASKS = "reach-v3,push-v3,pick-place-v3,peg-insert-side-v3"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="results/sft/policy")
    parser.add_argument("--wm", default="results/world_model/wm")
    parser.add_argument("--reward", default="judge:results/judge/one_camera/judge")
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
    scenes = scenes_for(resolve_tasks(args.tasks), args.scenes_per_task)
    run_spec = RLRun(policy=args.policy, env=env_kind("imagined"), reward=RewardSpec.parse(args.reward), wm=args.wm)
    settings = practice_settings(RLConfig(group_size=args.group_size, lr=args.lr, watch_rollouts=args.watch_rollouts,
                                          workers=1), args.steps, args.starts_per_step)
    if args.report_only:
        scenes = [scene for scene in scenes if (args.out / f"{scene[0]}_{scene[1]}" / "summary.json").exists()]
    rows = practise(run_spec, settings, scenes, args.out)
    if not rows:  # never overwrite a committed table with an empty one
        sys.exit(f"no scene practised under {args.out}: nothing to tabulate")
    results = {"command": " ".join(sys.argv), "settings": {"run": run_spec.to_json(), "rl": vars(settings)},
               "scenes": rows, "totals": totals(rows)}
    write_json(RESULTS / "practice.json", results)
    text = "\n".join(table(rows, results["totals"]))
    (RESULTS / "practice.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
