"""The imagination measurement's files: imagination.json, imagination.md, psnr.png and videos/.

Legend: T actions per rollout, H/W image size.

Everything is drawn from the report `gymnast.experiment.imagination.measure_imagination` returns,
plus the frames of the few rollouts shown as videos.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from gymnast.experiment.formatting import ci, pct
from gymnast.utils.atomic import write_bytes, write_json

logger = logging.getLogger(__name__)


def write_imagination_report(report: dict, videos: list[tuple[dict, np.ndarray, np.ndarray]], out: Path) -> dict:
    """Writes the videos, the PSNR plot, imagination.md and imagination.json into `out`.

    Args:
        report: `measure_imagination`'s figures (its ``videos`` and ``files`` are filled in here).
        videos: (scene record, imagined (T + 1, H, W, 3) uint8, replayed (T + 1, H, W, 3) uint8).
        out: the directory (created if missing).

    Returns:
        The report with ``videos`` (one entry per video: ``path`` relative to `out`, ``task``,
        ``seed``, ``kind``) and ``files`` (``json``, ``markdown``, ``plot``: paths relative to `out`).
    """
    from gymnast.envs.metaworld import CONTROL_FPS
    from gymnast.world_model.videos import write_side_by_side

    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for n, (row, imagined, replayed) in enumerate(videos):
        name = f"videos/{n:02d}_{row['kind']}_{row['task'].removesuffix('-v3')}_seed{row['seed']}.mp4"
        # The helper's first panel is the one named "real"; imagined goes first here, as the title says.
        write_side_by_side(out / name, imagined, replayed, fps=CONTROL_FPS)
        entries.append({"path": name, "task": row["task"], "seed": row["seed"], "kind": row["kind"]})
    report = {**report, "videos": entries,
              "files": {"json": "imagination.json", "markdown": "imagination.md", "plot": "psnr.png"}}
    plot_psnr(report, out / "psnr.png")
    write_bytes(out / "imagination.md", imagination_markdown(report).encode())
    write_json(out / "imagination.json", report)
    logger.info("imagination report: %s", out / "imagination.md")
    return report


def plot_psnr(report: dict, path: Path) -> Path:
    """Mean PSNR of the imagined frames against the real replay at each step, whole frame and
    moving pixels."""
    from gymnast.experiment.plots import _figure, _save

    plt, figure, axes = _figure(6.4, 4.0)
    figures = report["psnr"]
    for key, label in (("curve", "whole frame"), ("moving_curve", "moving pixels")):
        values = np.array([np.nan if v is None else v for v in figures[key]], dtype=float)
        axes.plot(np.arange(1, len(values) + 1), values, label=label)
    axes.set_xlabel("step (actions since the real start frame)")
    axes.set_ylabel("PSNR vs real replay (dB)")
    overall = report["overall"]
    axes.set_title(f"Imagined vs real frames of the same actions ({overall['episodes']} scenes, closed loop)", fontsize=10)
    axes.legend(fontsize=8)
    return _save(plt, figure, path)


def _db(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


def _rate(rate: dict) -> str:
    if rate["success"] is None:
        return "-"
    return f"{pct(rate['success'])} {ci(rate)} ({rate['successes']}/{rate['episodes']})"


def _overall(block: dict) -> list[str]:
    counts, judge = block["confusion"], block["judge_on_real"]
    return [
        "| measure | value |", "|---|---|",
        f"| imagined success (judged), 95% CI | {_rate(block['imagined_success'])} |",
        f"| real replay of the imagined actions | {_rate(block['replay_success'])} |",
        f"| policy closed loop in the real world | {_rate(block['real_success'])} |",
        f"| agreement of the imagined verdict with the replay | **{pct(block['agreement'])}** ({block['judged']} judged) |",
        f"| false success (judged successes that failed on replay) | {pct(block['false_success'])} |",
        f"| missed success (replay successes judged failures) | {pct(block['missed_success'])} |",
        (f"| the judge on the closed-loop real videos | agreement {pct(judge['agreement'])}, TPR {pct(judge['tpr'])}, "
         f"FPR {pct(judge['fpr'])} ({judge['judged']} judged) |"),
        "", "| imagined verdict \\ real replay | success | failure |", "|---|---|---|",
        f"| judged success | {counts['tp']} (tp) | {counts['fp']} (fp) |",
        f"| judged failure | {counts['fn']} (fn) | {counts['tn']} (tn) |",
    ]


def _per_task(report: dict) -> list[str]:
    lines = ["| task | scenes | tp | fp | fn | tn | agreement | imagined | replay | closed loop | judge on real (agreement) "
             "| PSNR (dB) |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for task, block in report["per_task"].items():
        counts = block["confusion"]
        lines.append(f"| {task} | {block['episodes']} | {counts['tp']} | {counts['fp']} | {counts['fn']} | {counts['tn']} | "
                     f"{pct(block['agreement'])} | {pct(block['imagined_success']['success'])} | "
                     f"{pct(block['replay_success']['success'])} | {pct(block['real_success']['success'])} | "
                     f"{pct(block['judge_on_real']['agreement'])} | {_db(block['psnr_full'])} |")
    return lines


def _psnr(report: dict) -> list[str]:
    figures = report["psnr"]
    names = [key.removeprefix("psnr_") for key in figures if key.startswith("psnr_")]
    lines = ["| pixels | " + " | ".join(f"step {n[1:]}" if n.startswith("h") else n for n in names) + " |",
             "|---|" + "---|" * len(names)]
    for prefix, title in (("psnr_", "whole frame"), ("moving_psnr_", "moving (changed since the start frame)")):
        lines.append(f"| {title} | " + " | ".join(_db(figures[prefix + n]) for n in names) + " |")
    return lines


def imagination_markdown(report: dict) -> str:
    """imagination.md: the figures of `report` as tables a reader can check."""
    settings, overall = report["settings"], report["overall"]
    who = ", ".join(f"{key} `{settings[key]}`" for key in ("policy", "wm", "reward") if key in settings)
    interactions, seconds = report["interactions"], report["seconds"]
    lines = [
        "# Imagination under a policy: judged imagined outcomes against the real world", "",
        (f"{who or settings['policy_type']}. Tasks {settings['tasks']}, {settings['episodes']} evaluation scenes each, "
         f"horizon {settings['horizon']} actions, greedy. The policy is rolled out closed loop in the world model and the "
         "video judged; the same actions are replayed in the real world from the same scene (without stopping at success); "
         "the policy is also run closed loop in the real world, and those videos judged too (the judge's own error)."), "",
        "## Overall", "", *_overall(overall), "",
        "## Per task", "", *_per_task(report), "",
        "## Imagined frames against the real replay (PSNR, dB)", "", *_psnr(report), "",
        f"![PSNR per step]({report['files'].get('plot', 'psnr.png')})", "",
    ]
    if report["videos"]:
        lines += ["## Videos (imagined | real replay | difference x3)", ""]
        lines += [f"- [{video['kind']}: {video['task']} seed {video['seed']}]({video['path']})" for video in report["videos"]]
        lines.append("")
    spent = ", ".join(f"{name} {value:.0f} s" for name, value in seconds.items())
    lines += ["## Cost", "",
              (f"Real interactions: {interactions['replay']:,} replaying, {interactions['real']:,} closed loop "
               f"({interactions['total']:,} in all). Time: {spent}.")]
    return "\n".join(lines) + "\n"


def format_imagination(report: dict) -> str:
    """Per task and overall, as aligned text: agreement, confusion counts and the three success rates."""
    rows = [("task", "scenes", "agreement", "tp/fp/fn/tn", "imagined", "replay", "closed loop", "false success")]
    for task, block in [*report["per_task"].items(), ("overall", report["overall"])]:
        counts = block["confusion"]
        rows.append((task, str(block["episodes"]), pct(block["agreement"]),
                     f"{counts['tp']}/{counts['fp']}/{counts['fn']}/{counts['tn']}", pct(block["imagined_success"]["success"]),
                     pct(block["replay_success"]["success"]), pct(block["real_success"]["success"]),
                     pct(block["false_success"])))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * width for width in widths))
    figures, judge = report["psnr"], report["overall"]["judge_on_real"]
    lines += ["", (f"PSNR vs real replay: {_db(figures['psnr_h1'])} dB at step 1, {_db(figures['psnr_h32'])} at 32, "
                   f"{_db(figures['psnr_full'])} over the rollout (moving pixels: {_db(figures['moving_psnr_full'])}); "
                   f"judge on real videos: TPR {pct(judge['tpr'])}, FPR {pct(judge['fpr'])}")]
    return "\n".join(lines)
