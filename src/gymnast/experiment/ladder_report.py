"""The learning ladder's report: OUT/summary.json, OUT/ladder.md and two plots, from the rungs' runs
(read by `gymnast.experiment.ladder_records`), so a ladder still under way reports the steps and
evaluations it has, and a rung's row says whether it finished. Per rung: real success at
its last evaluation with the 95% Wilson interval, the curve of every evaluation, the real
interactions it spent (training's, the truth's, the watch's and the evaluations'), the
reward-hacking watch at every evaluation, and `agreement_by_step`: how often the reward the policy
trained on agreed with the real outcome of the same rollouts at each step (`gymnast.rl.sight`).
`write_ladder_index` gathers several ladders (regimes, task sets) into one summary.json.
"""

from __future__ import annotations

from pathlib import Path

from gymnast.experiment.formatting import pct
from gymnast.experiment.ladder_records import fixed_arms, rung_record
from gymnast.experiment.plots import _figure, _save
from gymnast.experiment.rungs import RUNGS, rung_dir
from gymnast.rl.config import RLConfig
from gymnast.utils.atomic import read_json, write_bytes, write_json


def ladder_summary(out: Path, config: RLConfig) -> dict:
    """The ladder's summary.json: ``sft`` (every rung's step-0 evaluation; an arm that starts from
    another policy gives it only where no other does), one entry per rung of OUT that has evaluated,
    in the ladder's order, then the practice arms after a fix: `gymnast rl` runs with the ladder's
    recipe or Dyna loops in OUT/fixed and OUT/fixed_<lever> (`fixed_arms`), where there are, those
    from another policy last."""
    summary: dict = {}
    rungs = [*RUNGS.values(), *fixed_arms(out)]
    for rung in sorted(rungs, key=lambda rung: rung.own_start):  # the ladder's own start first; sorted() is stable
        record = rung_record(rung, rung_dir(out, rung), config.steps)
        if record is None:
            continue
        if "sft" not in summary:
            first = record["curve"][0]
            summary["sft"] = {"what": "the starting policy (every rung's step-0 evaluation)",
                              "success": first["success"], "ci_low": first["ci_low"], "ci_high": first["ci_high"],
                              "episodes": first["episodes"], "real_interactions": 0, "agreement_by_step": [],
                              "curve": [first]}
        summary[rung.name] = record
    return summary


def mean_agreement(record: dict, key: str = "agreement") -> float | None:
    """A rung's `key` averaged over the steps that measured it (None where none did)."""
    values = [row[key] for row in record["agreement_by_step"] if row.get(key) is not None]
    return sum(values) / len(values) if values else None


def ladder_table(summary: dict) -> str:
    """The ladder as a markdown table, one row per rung."""
    rows = ["| rung | real success [95% CI] | episodes | from | agreement (first -> last step) | false successes | "
            "signal | real interactions (training) | steps |", "|---|---|---|---|---|---|---|---|---|"]
    for name, record in summary.items():
        if name == "sft":
            rows.append(f"| sft | {pct(record['success'])} [{pct(record['ci_low'])}, {pct(record['ci_high'])}] | "
                        f"{record['episodes']} | | | | | 0 | |")
            continue
        agreement = [row["agreement"] for row in record["agreement_by_step"] if row.get("agreement") is not None]
        moved = f"{pct(agreement[0])} -> {pct(agreement[-1])}" if agreement else "n/a"
        false = mean_agreement(record, "false_success")
        signal = mean_agreement(record, "truth_signal")
        rows.append(f"| {name} | {pct(record['success'])} [{pct(record['ci_low'])}, {pct(record['ci_high'])}] | "
                    f"{record['episodes']} | {pct(record['start_success'])} | {moved} | {'n/a' if false is None else pct(false)} | "
                    f"{'n/a' if signal is None else f'{signal:+.2f}'} | {record['real_interactions']:,} | "
                    f"{record['steps_done']}{'' if record['finished'] else ' (under way)'} |")
    return "\n".join(rows)


def write_ladder_report(out: Path, config: RLConfig) -> dict:
    """Writes OUT/summary.json, OUT/ladder.md, OUT/curves.png and OUT/agreement.png; returns the summary."""
    summary = ladder_summary(out, config)
    write_json(out / "summary.json", summary)
    if len(summary) > 1:
        plot_ladder_curves(summary, out / "curves.png")
        plot_ladder_agreement(summary, out / "agreement.png")
    lines = ["# The learning ladder", "",
             f"{config.steps} GRPO steps of {config.starts_per_step} x {config.group_size} rollouts on {config.tasks}, "
             f"real success at the last evaluation, the recipe's on {config.eval_episodes} evaluation seeds per task (a "
             "row's own episodes beside it; 95% Wilson intervals). Agreement: how "
             "often the reward's verdict equals the real outcome of the same rollouts (first and last step measured); "
             "false successes: the share of its successes that fail for real (mean over steps); signal: the "
             "correlation of its group advantages with the real outcomes (mean over steps).", "",
             ladder_table(summary), "", "| rung | what it swaps |", "|---|---|",
             *[f"| {name} | {summary[name]['what']} |" for name in summary if name != "sft"], "",
             "Plots: curves.png (real success by step), agreement.png (agreement by step).", ""]
    write_bytes(out / "ladder.md", "\n".join(lines).encode())
    return summary


def write_ladder_index(root: Path) -> dict:
    """ROOT/summary.json: every ladder under ROOT (a summary.json beside a ladder.md), nested by its
    path, e.g. ROOT/scarce/mt10 as ``{"scarce": {"mt10": {...}}}``."""
    index: dict = {}
    for report in sorted(root.rglob("ladder.md")):
        where = report.parent.relative_to(root).parts
        if not where:
            continue
        node = index
        for part in where[:-1]:
            node = node.setdefault(part, {})
        node[where[-1]] = read_json(report.parent / "summary.json")
    write_json(root / "summary.json", index)
    return index


def plot_ladder_curves(summary: dict, path: Path) -> Path:
    """Real success against RL step, one line per rung, SFT as a horizontal line; the rungs' 95%
    intervals shaded (the fix arms', beside so many lines, would hide them: the table gives them)."""
    plt, figure, axes = _figure(8.0, 5.2)
    styles = _line_styles(summary)
    for name, record in summary.items():
        if name == "sft":
            axes.axhline(record["success"], color="grey", linestyle="--", label="SFT")
            continue
        steps = [point["step"] for point in record["curve"]]
        axes.plot(steps, [point["success"] for point in record["curve"]], label=name, **styles[name])
        if name in RUNGS:
            axes.fill_between(steps, [p["ci_low"] for p in record["curve"]],
                              [p["ci_high"] for p in record["curve"]], color=styles[name]["color"], alpha=0.08)
    return _by_step(plt, figure, axes, "real-world success", "The learning ladder: real success by step (95% CI)", path)


def plot_ladder_agreement(summary: dict, path: Path) -> Path:
    """Each rung's agreement of its reward with the real outcome, step by step."""
    plt, figure, axes = _figure(8.0, 5.2)
    styles = _line_styles(summary)
    for name, record in summary.items():
        points = [row for row in record["agreement_by_step"] if row.get("agreement") is not None]
        if points:
            axes.plot([row["step"] for row in points], [row["agreement"] for row in points], label=name,
                      **styles[name])
    return _by_step(plt, figure, axes, "reward verdict = real outcome",
                    "Does the reward still tell the truth as the policy moves?", path)


def _line_styles(summary: dict) -> dict[str, dict]:
    """A line style per row that no other row of up to 20 arms shares: the ladder's rungs solid with
    round markers (tab10), the fix arms dashed or dotted with square ones (tab20b: five hues, each
    hue's darker shades first)."""
    import matplotlib

    rung_colours = matplotlib.colormaps["tab10"].colors
    arm_colours = matplotlib.colormaps["tab20b"].colors
    order = [hue * 4 + shade for shade in (0, 2, 1, 3) for hue in range(5)]
    styles = {}
    for i, name in enumerate(name for name in summary if name in RUNGS):
        styles[name] = {"color": rung_colours[i % 10], "linestyle": "-", "marker": "o"}
    for i, name in enumerate(name for name in summary if name != "sft" and name not in RUNGS):
        styles[name] = {"color": arm_colours[order[i % 20]], "linestyle": ("--", ":")[i % 2], "marker": "s",
                        "markersize": 4}
    return styles


def _by_step(plt, figure, axes, ylabel: str, title: str, path: Path) -> Path:
    """Labels a plot of rates against RL steps, one line per rung, and saves it."""
    axes.set_xlabel("RL step")
    axes.set_ylabel(ylabel)
    axes.set_ylim(0, 1.05)
    axes.set_title(title, fontsize=10)
    axes.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    return _save(plt, figure, path)

