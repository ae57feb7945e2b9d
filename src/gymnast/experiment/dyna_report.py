"""What `gymnast dyna` writes: OUT/summary.json, the table OUT/dyna.md and the plot OUT/dyna.png
(real success against real interactions spent on training, Dyna beside RL in the real world)."""

from __future__ import annotations

from pathlib import Path

from gymnast.experiment.plots import _figure, _save
from gymnast.experiment.formatting import ci, pct
from gymnast.utils.atomic import atomic_path, write_json
from gymnast.utils.trackers import open_trackers


def write_report(summary: dict, out: Path) -> dict:
    """Writes the summary, the table and the plot into `out`; returns the summary with their names."""
    summary = {**summary, "table": "dyna.md", "plot": "dyna.png"}
    plot_dyna(summary, out / summary["plot"])
    with atomic_path(out / summary["table"]) as tmp:
        Path(tmp).write_text(dyna_table(summary) + "\n")
    write_json(out / "summary.json", summary)
    return summary


def track_report(summary: dict, out: Path, tracker: tuple[str, ...], settings: dict) -> None:
    """Each round's real success and training interactions (a step per round), the real-world arm's
    at the same boundaries, and the plot, to the trackers `tracker` as one run in `out`."""
    steps: dict[int, dict[str, float]] = {}  # one call a step: W&B takes steps in order
    for row in summary["rounds"]:
        steps.setdefault(row["round"], {}).update({
            "eval/dyna_success": row["success"], "eval/dyna_ci_low": row["ci_low"], "eval/dyna_ci_high": row["ci_high"],
            "rollout/dyna_real_interactions": row["real_interactions"]})
    for k, point in enumerate((summary["real_rl"] or {}).get("curve", [])):  # evaluated at every round's boundary
        steps.setdefault(k, {}).update({"eval/real_rl_success": point["success"],
                                        "rollout/real_rl_real_interactions": point["real_interactions"]})
    trackers = open_trackers(tracker, out, kind="dyna", config=settings)
    for step, values in sorted(steps.items()):
        trackers.log_metrics(step, values)
    trackers.log_image("plots/dyna", len(summary["rounds"]) - 1, out / summary["plot"])
    trackers.close()


def dyna_table(summary: dict) -> str:
    """Markdown: each Dyna round and each real-world RL evaluation, with its real success and the
    real interactions spent on training by then."""
    lines = [f"Real success on {summary['tasks']} ({summary['eval_episodes_per_task']} evaluation episodes per task, "
             "95% Wilson intervals); real interactions are actions taken in the real world for training, "
             "cumulative; evaluations and RL's checks are counted apart.", "",
             "| arm | round | RL steps | real success | 95% CI | real interactions (training) | "
             "real interactions (measurement) |", "|---|---|---|---|---|---|---|"]
    for row in summary["rounds"]:
        lines.append(f"| Dyna | {row['round']} | {row['rl_steps']} | {pct(row['success'])} | {ci(row)} | "
                     f"{row['real_interactions']:,} | {row['measurement_real_interactions']:,} |")
    for point in (summary["real_rl"] or {}).get("curve", []):
        lines.append(f"| RL in the real world | - | {point['step']} | {pct(point['success'])} | {ci(point)} | "
                     f"{point['real_interactions']:,} | - |")
    return "\n".join(lines)


def plot_dyna(summary: dict, path: Path) -> Path:
    """Real success (95% band) against real training interactions, one line per arm."""
    plt, figure, axes = _figure(7.0, 4.4)
    arms = [("Dyna (imagined RL + real rollouts)", summary["rounds"])]
    if summary["real_rl"]:
        arms.append(("RL in the real world", summary["real_rl"]["curve"]))
    for label, points in arms:
        spent = [max(p["real_interactions"], 1) for p in points]  # a log axis has no 0: the start sits at 1
        axes.plot(spent, [p["success"] for p in points], marker="o", label=label)
        axes.fill_between(spent, [p["ci_low"] for p in points], [p["ci_high"] for p in points], alpha=0.15)
    axes.set_xscale("log")
    axes.set_xlabel("real interactions spent on training (actions; the start at 1)")
    axes.set_ylabel("real-world success")
    axes.set_ylim(0, 1.05)
    axes.set_title(f"Real success against real interactions ({summary['tasks']})", fontsize=10)
    axes.legend(fontsize=8)
    return _save(plt, figure, path)
