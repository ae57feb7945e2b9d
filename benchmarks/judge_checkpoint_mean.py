"""A per-frame judge whose frame probability is the mean of several of its run's checkpoints: does
averaging the stages of one training run pass more successes at a low false-success rate?

For every combination of the checkpoints asked for, each frame's probability is the members' mean,
the hold rules asked for are applied to it, and the calibration episodes choose the hold rule and
the threshold as `gymnast calibrate-judge` does (the most successes passed at FPR <= `--max-fpr`);
the run's held-out real videos are then judged with that choice. One checkpoint alone is the
calibration `gymnast calibrate-judge` makes. The per-frame probabilities are computed once per
checkpoint and shared by every combination.

    python benchmarks/judge_checkpoint_mean.py --judge runs/headline_three/judge \\
        --data data/calibration_three data/calibration_three_policy --checkpoints 500 1000 1500 2000 \\
        --out benchmarks/results/judge_checkpoint_mean_headline_three.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import torch

from gymnast.reward.judges.calibrate import calibration_cases, case_frame_probabilities, frame_judge
from gymnast.reward.judges.frames import held_probability
from gymnast.reward.judges.measure import threshold_at_fpr
from gymnast.reward.judges.train import run_scene_videos
from gymnast.reward.judges.videos import judge_cases
from gymnast.utils.atomic import write_json
from gymnast.utils.checkpoint import checkpoint_at


def held_scores(members: list[list[torch.Tensor]], hold: int) -> torch.Tensor:
    """(N,) each case's held probability of the members' mean per-frame probabilities; `members`
    holds one list of (T,) probabilities per checkpoint."""
    return torch.stack([held_probability(torch.stack(frames).mean(dim=0)[None], hold)[0]
                        for frames in zip(*members)]).double()


def rates(scores: torch.Tensor, truth: torch.Tensor, threshold: float) -> dict[str, float]:
    passed = scores >= threshold
    return {"tpr": round((passed & truth).sum().item() / truth.sum().item(), 4),
            "fpr": round((passed & ~truth).sum().item() / (~truth).sum().item(), 4)}


def measure(run: Path, data: list[Path], checkpoints: list[int], holds: list[int], max_fpr: list[float]) -> dict:
    cases, truth = calibration_cases(run, data, progress=True)
    heldout = [(video, len(frames), label) for video in run_scene_videos(run, 2)
               for frames, _, label, _, imagined in judge_cases([video]) if not imagined]
    heldout_truth = torch.tensor([label for *_, label in heldout])
    probabilities = {}
    for step in checkpoints:
        judge = frame_judge(checkpoint_at(run, step))
        probabilities[step] = (case_frame_probabilities(judge, cases),
                               case_frame_probabilities(judge, [(video, length) for video, length, _ in heldout]))
    rows = []
    for rate in max_fpr:
        for size in range(1, len(checkpoints) + 1):
            for members in itertools.combinations(checkpoints, size):
                options = [(hold, threshold_at_fpr(held_scores([probabilities[m][0] for m in members], hold),
                                                   truth, rate)) for hold in holds]
                # The most calibration successes at the allowed rate, then the fewest failures.
                hold, chosen = max(options, key=lambda option: (option[1]["tpr"], -option[1]["fpr"]))
                heldout_scores = held_scores([probabilities[m][1] for m in members], hold)
                rows.append({"max_fpr": rate, "checkpoints": list(members), "hold_steps": hold,
                             "threshold": chosen["threshold"], "calibration_tpr": chosen["tpr"],
                             "calibration_fpr": chosen["fpr"],
                             **{f"heldout_{k}": v for k, v in rates(heldout_scores, heldout_truth,
                                                                    chosen["threshold"]).items()}})
                print(json.dumps(rows[-1]))
    return {"judge": str(run), "calibration_data": [str(path) for path in data], "calibration_cases": len(truth),
            "calibration_positives": int(truth.sum()), "heldout_cases": len(heldout_truth),
            "heldout_positives": int(heldout_truth.sum()), "rows": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--judge", type=Path, required=True, help="a per-frame judge run (gymnast train-judge)")
    parser.add_argument("--data", type=Path, nargs="+", required=True, help="labelled real episodes recorded apart")
    parser.add_argument("--checkpoints", type=int, nargs="+", required=True, help="steps of the run's checkpoints")
    parser.add_argument("--holds", type=int, nargs="+", default=[5, 8, 12], help="hold rules to choose among")
    parser.add_argument("--max-fpr", type=float, nargs="+", default=[0.02, 0.03])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/judge_checkpoint_mean.json"))
    args = parser.parse_args()
    result = measure(args.judge, args.data, args.checkpoints, args.holds, args.max_fpr)
    write_json(args.out, result | {"command": " ".join(["benchmarks/judge_checkpoint_mean.py", *sys.argv[1:]])})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
