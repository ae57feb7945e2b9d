"""The levers against exploiting the world model, side by side on reach-v3 with the reward-hacking
watch: no lever, a stop where the world-model ensemble disagrees, MOPO's penalty on disagreement,
a KL anchor to the SFT policy and an imitation anchor on expert demonstrations (docs/rl.md,
"Resisting exploitation").

Every arm is one `gymnast rl` run in the ensemble's imagination with the judge reward and the
same seed, settings and start draws; only its lever differs. The no-lever arm runs first, and the
stop's threshold and the penalty's weight are read off its first step unless given: the stop at
the mean of the rollouts' worst-frame disagreement, the penalty so that it takes 0.5 (half a
success) from a rollout of mean disagreement.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/rl_levers.py [--wm runs/wm_ensemble] [--steps 3] [--real-eval]

The defaults fit a shared 2-core CPU (about 7 minutes an arm): 4 starts x 8 rollouts a step, one
round, the watch replaying 16 rollouts after every step. Exploitation grew over tens of steps in
the runs of results/rl/, so a longer run (``--steps 15 --real-eval``) is what says whether the
penalty and the KL anchor, which act through learning, matter; the stop acts from the first step.

Writes runs/levers/<arm>/ and results/rl/levers/ (each arm's config, summary and metrics,
levers.json and levers.md; ``--results`` elsewhere). ``--arms`` runs some arms only: the others
already in ``--out`` are tabulated beside them, and the no-lever arm there still sets the stop and
the penalty.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

from gymnast.utils.atomic import write_json
from gymnast.utils.metrics import read_metrics

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl" / "levers"
ARMS = ("none", "stop", "penalty", "kl", "imitation")
WATCH = ("eval/watch_imagined_success", "eval/watch_false_success", "eval/watch_real_success", "eval/watch_agreement")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wm", default="runs/wm_ensemble", help="a world-model ensemble (gymnast make-ensemble)")
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--eval-episodes", type=int, default=10, help="imagined evaluation episodes at both ends")
    parser.add_argument("--real-eval", action="store_true", help="also evaluate in the real world (slow)")
    parser.add_argument("--lr", type=float, default=1e-4, help="high enough to exploit the judge within the steps")
    parser.add_argument("--stop", type=float, help="disagreement stop threshold (default: from the no-lever arm)")
    parser.add_argument("--penalty", type=float, help="disagreement penalty weight (default: from the no-lever arm)")
    parser.add_argument("--kl", type=float, default=0.1, help="KL anchor weight")
    parser.add_argument("--imitation", type=float, default=0.1, help="imitation anchor weight (VLA-RFT's auxiliary loss)")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "levers")
    parser.add_argument("--arms", default=",".join(ARMS), help=f"the arms to run, of {','.join(ARMS)}")
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the measurements are kept")
    parser.add_argument("--report-only", action="store_true", help="only tabulate the arms already run in --out")
    args = parser.parse_args()
    chosen = [arm.strip() for arm in args.arms.split(",") if arm.strip()]
    if unknown := sorted(set(chosen) - set(ARMS)):
        parser.error(f"--arms: unknown {', '.join(unknown)}; choose from {', '.join(ARMS)}")
    if args.report_only:
        chosen = []
    results = {"command": " ".join(sys.argv), "arms": {}}
    common = ["--policy", "results/sft/policy", "--env", "imagined", "--wm", args.wm,
              "--reward", "judge:results/judge/one_camera/judge", "--data", "data/mt10", "--tasks", "reach-v3",
              "--steps", str(args.steps), "--starts-per-step", "4", "--group-size", "8", "--lr", str(args.lr),
              "--max-rounds", "1", "--eval-every", "0", "--eval-episodes", str(args.eval_episodes),
              "--watch-every", "1", "--watch-rollouts", "16", "--video-every", str(args.steps),
              "--checkpoint-every", str(args.steps), "--workers", "2",
              "--real-eval" if args.real_eval else "--no-real-eval"]
    if "none" in chosen:
        results["arms"]["none"] = train("none", [], common, args.out, args.results)
    elif (args.out / "none" / "summary.json").exists():
        results["arms"]["none"] = measure(args.out / "none", args.results)
    first = results["arms"].get("none", {}).get("first_step", {})
    levers = {"stop": lambda: ["--disagreement-stop", f"{args.stop or first['rollout/disagreement_max']:.6g}"],
              "penalty": lambda: ["--disagreement-penalty", f"{args.penalty or 0.5 / first['rollout/disagreement_mean']:.6g}"],
              "kl": lambda: ["--kl-coef", str(args.kl)],
              "imitation": lambda: ["--imitation-coef", str(args.imitation)]}
    for arm, lever in levers.items():
        if arm in chosen:
            if arm in ("stop", "penalty") and not first and getattr(args, arm) is None:
                parser.error(f"--arms {arm} needs the no-lever arm in {args.out / 'none'} (or --{arm})")
            results["arms"][arm] = train(arm, lever(), common, args.out, args.results)
        elif (args.out / arm / "summary.json").exists() and arm not in results["arms"]:
            results["arms"][arm] = measure(args.out / arm, args.results)
    report(results, args.results)


def report(results: dict, kept: Path) -> None:
    write_json(kept / "levers.json", results)
    (kept / "levers.md").write_text(table(results))
    print(table(results))


def train(arm: str, lever: list[str], common: list[str], out: Path, kept: Path) -> dict:
    """Runs one arm (afresh) and copies what it measured to `kept`/<arm>/."""
    run = out / arm
    shutil.rmtree(run, ignore_errors=True)
    subprocess.run([sys.executable, "-m", "gymnast.cli", "rl", *common, *lever, "--out", str(run)], check=True, cwd=ROOT)
    return measure(run, kept)


def measure(run: Path, kept: Path) -> dict:
    """What one arm's run measured; its config, summary and metrics are copied to `kept`/<arm>/."""
    kept = kept / run.name
    kept.mkdir(parents=True, exist_ok=True)
    for name in ("config.json", "summary.json", "metrics.jsonl"):
        shutil.copy(run / name, kept / name)
    metrics = read_metrics(run)
    steps = [m for m in metrics if "reward/mean" in m]
    watched = [m for m in metrics if "eval/watch_real_success" in m]
    summary = json.loads((run / "summary.json").read_text())
    settings = json.loads((run / "config.json").read_text())["rl"]
    levers = {"disagreement_stop": "--disagreement-stop", "disagreement_penalty": "--disagreement-penalty",
              "kl_coef": "--kl-coef", "imitation_coef": "--imitation-coef"}
    return {
        "lever": " ".join(f"{flag} {settings[name]:.4g}" for name, flag in levers.items() if settings.get(name)) or "none",
        "wall_s": summary["wall_s"],
        "first_step": steps[0],
        "judged_train_success": [m.get("rollout/success") for m in steps],
        "disagreement_mean": [m.get("rollout/disagreement_mean") for m in steps],
        "stopped": [m.get("rollout/stopped") for m in steps],
        "watch": [{"step": m["step"], **{key: m.get(key) for key in WATCH}} for m in watched],
        "watch_false_success": pooled_false_success(watched),
        **{key: summary[key] for key in ("start_success", "end_success", "start_real_success", "end_real_success",
                                         "start_real_ci", "end_real_ci")},
    }


def pooled_false_success(watched: list[dict]) -> dict:
    """The watched judged successes of every check (16 replays each) and how many failed in the real world."""
    judged = [round(m.get("eval/watch_imagined_success", 0.0) * 16) for m in watched]
    false = [round(m.get("eval/watch_false_success", 0.0) * count) for m, count in zip(watched, judged)]
    return {"judged": sum(judged), "failed": sum(false), "share": sum(false) / sum(judged) if sum(judged) else None}


def table(results: dict) -> str:
    lines = ["| arm | lever | judged success of the training rollouts, per step | judged success in imagination, "
             "eval start -> end | real success start -> end | watch: judged successes failing in the real world | "
             "mean disagreement, first -> last step | stopped |",
             "|---|---|---|---|---|---|---|---|"]
    for arm, r in results["arms"].items():
        d = [x for x in r["disagreement_mean"] if x is not None]
        stopped = [x for x in r["stopped"] if x is not None]
        watch = r["watch_false_success"]
        lines.append(f"| {arm} | `{r['lever']}` | {', '.join(pct(x) for x in r['judged_train_success'])} | "
                     f"{pct(r['start_success'])} -> {pct(r['end_success'])} | "
                     f"{pct(r['start_real_success'])} -> {pct(r['end_real_success'])} {interval(r['end_real_ci'])} | "
                     f"{watch['failed']}/{watch['judged']} ({pct(watch['share'])}) | "
                     f"{f'{d[0]:.4f} -> {d[-1]:.4f}' if d else 'n/a'} | "
                     f"{pct(sum(stopped) / len(stopped)) if stopped else 'n/a'} |")
    return "\n".join(lines) + "\n"


def pct(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.0f}%"


def interval(ci: list) -> str:
    return "" if None in ci else f"[{100 * ci[0]:.0f}%, {100 * ci[1]:.0f}%]"


if __name__ == "__main__":
    main()
