"""A trained per-frame judge under several hold rules: how many steps in a row must show the task
done (`JudgeConfig.hold_steps`) before a video counts as a success.

For each number of steps the threshold is chosen again on the run's own validation scenes (with
its `threshold_tpr` rule, as `gymnast train-judge` chose it), then the held-out real videos are
judged: TPR, FPR, and the ROC readouts that no threshold decides (AUC, the lowest FPR at TPR 0.95,
the best TPR at FPR 0.03). The per-frame probabilities are computed once and reused by every rule.
`--threshold-tpr` chooses every threshold for that validation TPR instead; `--checkpoint` measures
an earlier checkpoint of the run (its step), as if training had stopped there.

    python benchmarks/judge_hold.py --judge runs/headline/judge --steps 1 3 5 8 \\
        --out benchmarks/results/judge_hold.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

import torch

from gymnast.reward.judges.base import ThresholdJudge
from gymnast.reward.judges.frames import FrameJudge, held_probability
from gymnast.reward.judges.measure import choose_threshold, evaluate_judge, operating_points
from gymnast.reward.judges.train import load_judge, run_scene_videos, saved_judge_config
from gymnast.reward.judges.videos import judge_cases
from gymnast.utils.atomic import write_json
from gymnast.utils.checkpoint import checkpoint_at

GOAL_FPR = 0.03


class HeldJudge(ThresholdJudge):
    """`judge` with another hold rule (and threshold), its per-frame probabilities of each video
    computed once and shared by every rule (`cache`)."""

    backend = FrameJudge.backend

    def __init__(self, judge: FrameJudge, steps: int, cache: dict) -> None:
        self.judge, self.cache = judge, cache
        self.config = dataclasses.replace(judge.config, hold_steps=steps)

    def probability(self, videos: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        key = (videos.data_ptr(), tuple(videos.shape), tuple(instructions))
        if key not in self.cache:
            self.cache[key] = self.judge.frame_probabilities(videos, instructions)
        return held_probability(self.cache[key], self.config.hold_steps)


def best_tpr_at(scores: torch.Tensor, truth: torch.Tensor, fpr: float) -> float:
    """The highest TPR any threshold gives on these cases at FPR <= `fpr` (0: a failure scores highest)."""
    _, passed, failed = operating_points(scores, truth)
    eligible = passed[failed <= fpr + 1e-9]
    return round(eligible.max().item(), 4) if len(eligible) else 0.0


def measure(run: Path, steps: Sequence[int], threshold_tpr: float | None = None, checkpoint: int | None = None) -> dict:
    """Each rule of `steps` on the judge `run` (its newest checkpoint, or that of step `checkpoint`),
    its threshold chosen with `threshold_tpr` (default: the run's rule)."""
    judge = load_judge(run if checkpoint is None else checkpoint_at(run, checkpoint))
    if not isinstance(judge, FrameJudge):
        raise ValueError(f"{run}: a {judge.backend}, not a per-frame judge; only those hold a success over steps")
    tpr = threshold_tpr if threshold_tpr is not None else saved_judge_config(run).threshold_tpr
    validation, heldout = (run_scene_videos(run, part) for part in (1, 2))
    cache, rows = {}, []
    for k in steps:
        held = HeldJudge(judge, k, cache)
        chosen = choose_threshold(held, validation, tpr)
        held.config = dataclasses.replace(held.config, threshold=chosen["threshold"])
        report = evaluate_judge(held, heldout)
        cases = [case for case in judge_cases(heldout) if not case[4]]
        scores = torch.cat([held.probability(frames[None], [text]) for frames, text, *_ in cases]).double()
        truth = torch.tensor([label for _, _, label, _, _ in cases])
        rows.append({"hold_steps": k, "threshold": chosen["threshold"], "validation_tpr": chosen["tpr"],
                     "validation_fpr": chosen["fpr"], **{key: report[key] for key in (
                         "real_tpr", "real_fpr", "real_fpr_whole_failures", "real_positives", "real_negatives")},
                     "real_auc": report["real_roc"]["auc"], "real_lowest_fpr_at_tpr_0.95": report["real_roc"]["lowest_fpr"],
                     f"real_best_tpr_at_fpr_{GOAL_FPR}": best_tpr_at(scores, truth, GOAL_FPR)})
        print(json.dumps(rows[-1]))
    measured = {"judge": str(run)} | ({} if checkpoint is None else {"checkpoint": checkpoint})
    return measured | {"trained_hold_steps": judge.config.hold_steps, "threshold_tpr": tpr,
                       "validation_episodes": len(validation), "heldout_episodes": len(heldout), "rows": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--judge", type=Path, required=True, help="a per-frame judge run (gymnast train-judge)")
    parser.add_argument("--steps", type=int, nargs="+", default=[1, 3, 5, 8], help="hold rules to measure")
    parser.add_argument("--threshold-tpr", type=float, default=None,
                        help="choose each threshold for this validation TPR (default: the run's rule)")
    parser.add_argument("--checkpoint", type=int, default=None, help="the step of an earlier checkpoint to measure")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/judge_hold.json"))
    args = parser.parse_args()
    write_json(args.out, measure(args.judge, args.steps, args.threshold_tpr, args.checkpoint))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
