"""The practice signal's figures and files: each readout's GRPO advantages held against those of the
real outcome (`signal_figures`, `signal_table`), signal.md (`format_signal`) and the brief the
experiment's summary.json keeps (`signal_brief`). What is measured, and why, is in
`gymnast.experiment.practice_signal`.

Legend: B start states (groups), G rollouts per start.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from gymnast.rl.grpo import group_advantages

SCORE = "score"
"""The readout of the reward's own score (a judge's verdict), as RL trains on it."""

PROBABILITY = "probability"
"""The readout of a learned judge's probability of success (its largest over the frames)."""

ON_REAL_VIDEO = ", real video (reference)"
"""Suffix of the readouts of the real replay's video: the reward's own error, without imagination's."""

VERDICT = "verdict"
"""The readout of a grounded world model's success verdict (success predicted at any step)."""

REAL_DENSE = "real dense reward (reference)"
"""The readout of the replay's own dense reward: a real-world signal, not imagination's."""

BOOTSTRAP = 1000
"""Resamplings of the groups behind each correlation's interval."""


def signal_table(records: list[dict], horizons: Sequence[int], group_size: int, binary: dict[str, bool]) -> list[dict]:
    """One row per readout and horizon: ``readout``, ``horizon`` and `signal_figures` over `records`
    (whole groups of `group_size`, in order)."""
    rows = []
    for name, is_binary in binary.items():
        for h in map(str, horizons):
            values = torch.tensor([r["readouts"][name][h] for r in records]).view(-1, group_size)  # (B, G)
            real = torch.tensor([r["real"][h] for r in records]).view(-1, group_size)  # (B, G)
            returns = torch.tensor([r["real_return"][h] for r in records]).view(-1, group_size)  # (B, G)
            rows.append({"readout": name, "horizon": int(h), **signal_figures(values, real, is_binary, returns)})
    return rows


def signal_figures(values: torch.Tensor, real: torch.Tensor, binary: bool, real_return: torch.Tensor | None = None,
                   seed: int = 0) -> dict:
    """How a readout's GRPO advantages agree with the real outcomes' (see the module docstring).

    Args:
        values: (B, G) the readout of each group's rollouts.
        real: (B, G) bool the real success of the same rollouts.
        binary: the readout is a 0/1 verdict (agreement and false successes are reported too).
        real_return: (B, G) the real dense return of the same rollouts, if known.
        seed: of the resampling behind the intervals.

    Returns:
        ``advantage_correlation`` with ``correlation_ci_low`` / ``_high`` (against real success),
        ``return_correlation`` with ``return_ci_low`` / ``_high`` (against the real dense return; None
        without it), ``reinforced_real_success``, ``discouraged_real_success``, ``signal_groups``,
        ``real_signal_groups``, ``groups``, ``real_success``, ``mean_readout``, and for binary readouts
        ``agreement``, ``imagined_success`` and ``false_success``; None where a share has nothing to
        divide by.
    """
    read, _ = group_advantages(values.float())  # (B, G)
    truth, _ = group_advantages(real.float())  # (B, G)
    groups = len(values)
    draws = torch.from_numpy(np.random.default_rng(seed).integers(0, groups, size=(BOOTSTRAP, groups)))  # resampled groups
    correlation, low, high = _correlation_interval(read, truth, draws)
    figures = {
        "groups": groups,
        "advantage_correlation": correlation,
        "correlation_ci_low": low,
        "correlation_ci_high": high,
        "return_correlation": None, "return_ci_low": None, "return_ci_high": None,
        "reinforced_real_success": _mean(real[read > 0]),
        "discouraged_real_success": _mean(real[read < 0]),
        "signal_groups": _mean((read != 0).any(dim=1)),
        "real_signal_groups": _mean((truth != 0).any(dim=1)),
        "real_success": _mean(real),
        "mean_readout": _mean(values),
    }
    if real_return is not None:
        returns, _ = group_advantages(real_return.float())  # (B, G)
        figures["return_correlation"], figures["return_ci_low"], figures["return_ci_high"] = \
            _correlation_interval(read, returns, draws)
    if binary:
        said = values > 0.5
        figures |= {"agreement": _mean(said == real), "imagined_success": _mean(said),
                    "false_success": _mean(~real[said])}
    return figures


def _correlation_interval(read: torch.Tensor, truth: torch.Tensor, draws: torch.Tensor
                          ) -> tuple[float | None, float | None, float | None]:
    """The advantage correlation of (B, G) `read` and `truth`, and its 95% interval over the
    (N, B) resampled groups `draws`."""
    resampled = [c for c in (_correlation(read[d], truth[d]) for d in draws) if c is not None]
    if not resampled:
        return _correlation(read, truth), None, None
    return _correlation(read, truth), float(np.percentile(resampled, 2.5)), float(np.percentile(resampled, 97.5))


def _correlation(read: torch.Tensor, truth: torch.Tensor) -> float | None:
    """Cosine of two advantage vectors; None where either is all zero (no group has spread)."""
    norm = float(read.square().sum().sqrt() * truth.square().sum().sqrt())
    return float((read * truth).sum()) / norm if norm > 0 else None


def _mean(values: torch.Tensor) -> float | None:
    return float(values.float().mean()) if values.numel() else None


def format_signal(report: dict) -> str:
    """signal.md: every readout's figures by horizon, then each task's at the longest horizon."""
    from gymnast.experiment.formatting import pct

    settings = report["settings"]
    lines = [
        "# Does practice in imagination push the policy where the real world would?", "",
        f"{settings['starts_per_task']} {_where(settings)} per task x {settings['group_size']} rollouts at temperature "
        f"{settings['temperature']}, imagined closed loop and replayed action for action in the real world "
        f"({report['interactions']:,} real interactions, {report['seconds']['total'] / 60:.1f} min). Tasks: "
        f"{', '.join(settings['task_list'])}. Advantage correlation: 1 = GRPO's update in imagination is the one the "
        "real outcomes would give; 0 = noise with respect to them (gymnast.experiment.practice_signal).", "",
        "| readout | horizon | advantage correlation with real success [95% CI] | with the real dense return [95% CI] "
        "| real success: reinforced / discouraged rollouts | groups ranked | agreement | false successes |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in report["readouts"]:
        lines.append(f"| {row['readout']} | {row['horizon']} | {_signed(row['advantage_correlation'])} "
                     f"[{_signed(row['correlation_ci_low'])}, {_signed(row['correlation_ci_high'])}] | "
                     f"{_signed(row.get('return_correlation'))} "
                     f"[{_signed(row.get('return_ci_low'))}, {_signed(row.get('return_ci_high'))}] | "
                     f"{pct(row['reinforced_real_success'])} / {pct(row['discouraged_real_success'])} | "
                     f"{pct(row['signal_groups'])} | {pct(row.get('agreement'))} | {pct(row.get('false_success'))} |")
    horizon = max(settings["horizons"])
    names = list(dict.fromkeys(row["readout"] for row in report["readouts"]))
    lines += ["", f"Per task at horizon {horizon}: the replays' real success and each readout's advantage correlation.",
              "", "| task | real success | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for task, rows in report["per_task"].items():
        longest = {row["readout"]: row for row in rows if row["horizon"] == horizon}
        cells = [_signed(longest[name]["advantage_correlation"]) for name in names]
        lines.append(f"| {task} | {pct(longest[names[0]]['real_success'])} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _where(settings: dict) -> str:
    """What the groups started from, in words."""
    if not settings.get("data"):
        return "fresh scenes"
    return f"keyframes ({settings['keyframes']}) of held-out episodes of {settings['data']}"


def _signed(value: float | None) -> str:
    return "-" if value is None else f"{value:+.2f}"


def signal_brief(report: dict, tasks: Sequence[str] | None = None) -> dict | None:
    """The main figures of a report at its longest horizon (what the experiment's summary.json
    keeps): for the reward's score on imagined video, the same on the real replay's video and the
    real dense reward, the advantage correlation with its interval and the real success of the
    reinforced and discouraged rollouts; and the rollouts (and, over every task, the real
    interactions) behind them.

    Args:
        report: `measure_signal`'s.
        tasks: pool only these tasks' groups (e.g. the weak ones); None: every task. None is
            returned where the report has none of them.
    """
    settings = report["settings"]
    horizon = max(settings["horizons"])
    if tasks is None:
        records, table, scope = report["rollouts"], report["readouts"], {"real_interactions": report["interactions"]}
    else:
        records = [r for r in report["rollouts"] if r["task"] in tasks]
        if not records:
            return None
        binary = {name: name in settings["binary_readouts"] for name in records[0]["readouts"]}
        table = signal_table(records, [horizon], settings["group_size"], binary)
        scope = {"tasks": sorted({r["task"] for r in records}, key=list(tasks).index)}
    rows = {row["readout"]: row for row in table if row["horizon"] == horizon}
    keys = ("advantage_correlation", "correlation_ci_low", "correlation_ci_high", "return_correlation",
            "return_ci_low", "return_ci_high", "reinforced_real_success", "discouraged_real_success", "signal_groups")
    return {"horizon": horizon, "rollouts": len(records), **scope,
            **{label: {key: rows[name].get(key) for key in keys} for label, name in
               (("imagined", SCORE), ("real_video", SCORE + ON_REAL_VIDEO), ("real_dense", REAL_DENSE))
               if name in rows}}
