"""A judge measured on held-out cases: its threshold chosen on validation scenes, TPR and FPR on
real and imagined videos apart, and how its P(success) ranks the cases apart from the threshold (ROC)."""

from __future__ import annotations

import logging

import torch

from gymnast.reward.base import Reward, RewardContext
from gymnast.reward.judges.base import ThresholdJudge
from gymnast.reward.judges.videos import Video, judge_cases

logger = logging.getLogger(__name__)

ROC_TPR = 0.95  # the TPR at which `roc_readout` finds the lowest FPR: the operating point the judge is held to


def choose_threshold(judge: Reward, videos: list[Video], tpr: float | None = None) -> dict:
    """The P(success) threshold that best separates the validation cases (most TPR - FPR, real and
    imagined together), or with `tpr`, the highest one whose TPR is at least `tpr`; in the middle
    of the range of equally good ones (or of the gap below the chosen score) so that it sits between
    scores rather than on one; 0.5 with no validation case of each label.

    Returns ``threshold``, ``tpr``, ``fpr`` and ``cases``.
    """
    cases = judge_cases(videos)
    truth = torch.tensor([label for _, _, label, _, _ in cases], dtype=torch.bool)
    if not truth.any() or truth.all():
        logger.warning("no validation scene with both outcomes: the judge keeps the threshold 0.5")
        return {"threshold": 0.5, "tpr": None, "fpr": None, "cases": len(cases)}
    scores = _probabilities(judge, cases).double()
    candidates, passed, failed = operating_points(scores, truth)
    if tpr is None:
        quality = passed - failed
        best = torch.nonzero(quality == quality.max()).flatten()
        first, last = int(best[0]), int(best[-1])
    else:  # the share passed falls as the threshold rises: the last candidate still at the rate
        first = last = int(torch.nonzero(passed >= tpr - 1e-9).flatten()[-1])
    return _operating_point(scores, truth, candidates, first, last) | {"cases": len(cases)}


def threshold_at_fpr(scores: torch.Tensor, truth: torch.Tensor, max_fpr: float) -> dict:
    """The threshold on (N,) `scores` of cases labelled (N,) `truth` (both labels present) that
    passes the most successes while passing at most `max_fpr` of the failures: the lowest whose FPR
    is within it, placed in the gap below its score. Returns ``threshold``, ``tpr`` and ``fpr``."""
    candidates, _, failed = operating_points(scores, truth)
    within = torch.nonzero(failed <= max_fpr + 1e-9).flatten()
    if not len(within):  # the highest score is a failure's and max_fpr allows none: pass nothing
        return {"threshold": float(candidates[-1]) + 1e-6, "tpr": 0.0, "fpr": 0.0}
    first = int(within[0])
    return _operating_point(scores, truth, candidates, first, first)


def _operating_point(scores: torch.Tensor, truth: torch.Tensor, candidates: torch.Tensor, first: int, last: int) -> dict:
    """The threshold midway between the candidate below `first` and candidate `last` (so that it sits
    between scores rather than on one), with the TPR and FPR it gives."""
    low = candidates[first - 1] if first > 0 else torch.tensor(0.0, dtype=torch.float64)
    threshold = float((low + candidates[last]) / 2)
    return {"threshold": threshold, "tpr": _rate(scores >= threshold, truth), "fpr": _rate(scores >= threshold, ~truth)}


def operating_points(scores: torch.Tensor, truth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every distinct threshold worth trying on (N,) scores of cases labelled (N,) `truth` (both
    labels present), ascending, with the TPR and FPR of ``scores >= threshold`` at each: a threshold
    in (candidates[i-1], candidates[i]] passes the same cases as candidates[i]."""
    candidates = torch.unique(scores)  # sorted
    passes = scores[None, :] >= candidates[:, None]  # (C, N)
    return candidates, passes[:, truth].double().mean(1), passes[:, ~truth].double().mean(1)


def roc_readout(scores: torch.Tensor, truth: torch.Tensor, at_tpr: float = ROC_TPR) -> dict:
    """How well P(success) ranks these cases, apart from the threshold the judge has: the ROC's AUC
    (the chance that a success outscores a failure, ties counting half) and the lowest FPR that any
    threshold gives here with TPR at least `at_tpr`. Both are chosen on the very cases they
    measure: an upper bound on what tuning the threshold could buy, not the judge as it runs.
    None with cases of one label only."""
    if not truth.any() or truth.all():
        return {"auc": None, "at_tpr": at_tpr, "lowest_fpr": None}
    positives, negatives = scores[truth], scores[~truth]
    above = (positives[:, None] > negatives[None, :]).double() + 0.5 * (positives[:, None] == negatives[None, :]).double()
    _, passed, failed = operating_points(scores, truth)
    return {"auc": round(above.mean().item(), 4), "at_tpr": at_tpr,
            "lowest_fpr": round(failed[passed >= at_tpr - 1e-9].min().item(), 4)}


def _probabilities(judge, cases: list[tuple[torch.Tensor, str, bool, bool, bool]]) -> torch.Tensor:
    """(N,) P(success) of each case, from a judge with a `probability`, in the judge's precision."""
    with torch.no_grad():
        return torch.cat([judge.probability(frames[None], [text]) for frames, text, _, _, _ in cases])


def evaluate_judge(judge: Reward, videos: list[Video]) -> dict:
    """TPR, FPR and accuracy of any 0/1 judge, real and imagined apart; FPR over all negatives and over
    whole failed episodes. A NaN verdict (could not score) counts as "not success" and is counted.
    A judge that gives P(success) (the learned ones) gets its verdicts from it and its threshold, and
    its ROC read out too (``real_roc``: `roc_readout`): is the threshold or the ranking at fault?"""
    report = {}
    for imagined in (False, True):
        cases = [case for case in judge_cases(videos) if case[4] == imagined]
        if not cases:
            continue
        truth = torch.tensor([label for _, _, label, _, _ in cases])
        prefix = "imagined" if imagined else "real"
        if isinstance(judge, ThresholdJudge):
            probabilities = _probabilities(judge, cases)
            verdicts = (probabilities >= judge.config.threshold).float()  # as `ThresholdJudge.score`
            report[f"{prefix}_roc"] = roc_readout(probabilities.double(), truth)
        else:
            verdicts = torch.stack([judge.score(f[None], [text], RewardContext())[0] for f, text, _, _, _ in cases])
        predicted = verdicts >= 0.5  # NaN compares False
        whole = torch.tensor([w for _, _, _, w, _ in cases])
        report |= {
            f"{prefix}_tpr": _rate(predicted, truth),
            f"{prefix}_fpr": _rate(predicted, ~truth),
            f"{prefix}_fpr_whole_failures": _rate(predicted, ~truth & whole),
            f"{prefix}_accuracy": round((predicted == truth).float().mean().item(), 4),
            f"{prefix}_positives": int(truth.sum()),
            f"{prefix}_negatives": int((~truth).sum()),
            f"{prefix}_whole_failures": int((~truth & whole).sum()),
            f"{prefix}_unscored": int(torch.isnan(verdicts).sum()),
        }
    return report


def _rate(predicted: torch.Tensor, among: torch.Tensor) -> float | None:
    """Share of `among` predicted positive (None when there are none)."""
    return round((predicted & among).sum().item() / among.sum().item(), 4) if among.any() else None
