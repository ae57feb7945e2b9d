"""The experiment's pictures: per-task success, learning curves, and the WorldGym scatter.

Each function draws from summary.json's content and writes one PNG atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gymnast.utils.atomic import atomic_path


def _figure(width: float, height: float):
    import matplotlib

    matplotlib.use("Agg")  # files only; no display
    import matplotlib.pyplot as plt

    return plt, *plt.subplots(figsize=(width, height), dpi=110)


def _save(plt, figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    plt.close(figure)
    return path


def plot_per_task(summary: dict, path: Path) -> Path:
    """Grouped bars: each arm's real success per task (and overall), with 95% Wilson intervals."""
    arms = summary["arms"]
    tasks = [*next(iter(arms.values()))["per_task"], "overall"]
    plt, figure, axes = _figure(max(7.0, 1.1 * len(tasks) + 3), 4.2)
    width = 0.8 / len(arms)
    x = np.arange(len(tasks))
    for i, row in enumerate(arms.values()):
        cells = [row["per_task"][task] for task in tasks[:-1]] + [row]
        values = np.array([cell["success"] for cell in cells])
        errors = np.array([[v - cell["ci_low"] for v, cell in zip(values, cells)],
                           [cell["ci_high"] - v for v, cell in zip(values, cells)]])
        axes.bar(x + (i - (len(arms) - 1) / 2) * width, values, width, yerr=errors, capsize=2, label=row["title"])
    axes.set_xticks(x, [task.removesuffix("-v3") for task in tasks], rotation=30, ha="right")
    axes.set_ylabel("real-world success")
    axes.set_ylim(0, 1.05)
    axes.set_title(f"Real-world success per task ({summary['eval_episodes_per_task']} episodes each, 95% CI)")
    axes.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    return _save(plt, figure, path)


def plot_curves(summary: dict, path: Path) -> Path:
    """Real success against RL step for each RL arm; SFT and Iter-SFT as horizontal lines."""
    plt, figure, axes = _figure(8.0, 5.6)
    for name, points in summary["curves"].items():
        points = [p for p in points if p["real"] is not None]
        steps = [p["step"] for p in points]
        axes.plot(steps, [p["real"] for p in points], marker="o", label=summary["arms"][name]["title"])
        axes.fill_between(steps, [p["real_ci"][0] for p in points], [p["real_ci"][1] for p in points], alpha=0.12)
    for name, style in (("sft", "--"), ("iter_sft", ":")):
        row = summary["arms"][name]
        axes.axhline(row["success"], color="grey", linestyle=style, label=f"{row['title']} (final evaluation)")
    axes.set_xlabel("RL step")
    axes.set_ylabel("real-world success")
    axes.set_ylim(0, 1.05)
    axes.set_title("Real-world success during RL (learning-curve evaluations, 95% CI)", fontsize=10)
    axes.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    return _save(plt, figure, path)


def plot_worldgym(summary: dict, path: Path) -> Path:
    """The experiment's WorldGym scatter (`plot_worldgym_rows` of summary.json's rows)."""
    return plot_worldgym_rows(summary["worldgym"], summary["worldgym_pearson"], summary["worldgym_spearman"], path)


def plot_worldgym_rows(rows: list[dict], pearson: float | None, spearman: float | None, path: Path) -> Path:
    """Imagined (judged) against real success, one point per policy with both 95% intervals, and
    the diagonal; the noise ladder's points (rows with a ``noise``) in their own colour."""
    plt, figure, axes = _figure(5.6, 5.4)
    axes.plot([0, 1], [0, 1], color="grey", linewidth=0.8, linestyle="--")
    labelled = set()
    for row in rows:
        ladder = row.get("noise") is not None
        label = "noise ladder" if ladder else "policies as trained"
        axes.errorbar(row["imagined"], row["real"],
                      xerr=[[row["imagined"] - row["imagined_ci"][0]], [row["imagined_ci"][1] - row["imagined"]]],
                      yerr=[[row["real"] - row["real_ci"][0]], [row["real_ci"][1] - row["real"]]],
                      fmt="s" if ladder else "o", color="tab:orange" if ladder else "tab:blue", capsize=2, alpha=0.8,
                      label=None if label in labelled else label)
        labelled.add(label)
        axes.annotate(row["policy"], (row["imagined"], row["real"]), fontsize=6, xytext=(3, 3), textcoords="offset points")
    title = "WorldGym: imagined vs real success (95% CI)"
    if pearson is not None:
        title += f"\nPearson r = {pearson:.2f}, Spearman = {spearman:.2f} ({len(rows)} policies)"
    axes.set_title(title, fontsize=10)
    axes.set_xlabel("success in the world model (judged)")
    axes.set_ylabel("success in the real world")
    axes.set_xlim(-0.02, 1.02)
    axes.set_ylim(-0.02, 1.02)
    axes.legend(fontsize=7, loc="best")
    return _save(plt, figure, path)
