"""The experiment's outputs: summary.json (figures), report.md (the story), plots/ (pictures).

Everything here is read back from the stage records and the runs' own files, so the report can
be rewritten at any time without running anything again.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from pathlib import Path

from gymnast.experiment.arms import ARMS, PERTURBATIONS, ROBUSTNESS_ARMS, WM_ARMS, arm
from gymnast.experiment.config import ExperimentConfig
from gymnast.experiment.formatting import number, ratio, wall_time
from gymnast.experiment.report.equal_time import equal_wall_clock
from gymnast.experiment.report.goals import experiment_goals
from gymnast.experiment.stages import BOOKKEEPING, Stages
from gymnast.utils.atomic import read_json, write_bytes, write_json

logger = logging.getLogger(__name__)


def _ratio(top: float | None, bottom: float | None) -> float | None:
    return None if top is None or not bottom else top / bottom


def _arm_row(stages: Stages, name: str, title: str) -> dict:
    result = stages.record(f"eval_{name}")
    trained = stages.record("sft" if name == "sft" else f"arm_{name}")
    return {"title": title, "success": result["success"], "ci_low": result["ci_low"], "ci_high": result["ci_high"],
            "episodes": result["episodes"],
            "per_task": {task: {k: v[k] for k in ("success", "ci_low", "ci_high")} for task, v in result["per_task"].items()},
            "real_interactions": trained.get("real_interactions", 0),
            "eval_real_interactions": trained.get("eval_real_interactions", 0) + result["real_interactions"],
            "watch_real_interactions": trained.get("watch_real_interactions", 0),
            "wall_s": trained.get("wall_s") if not trained.get("reused") else _logged_wall_s(Path(trained["path"])),
            "reused": trained.get("reused", False),
            "steps": trained.get("steps"), "videos": result.get("videos", [])}


def _logged_wall_s(run: Path) -> float | None:
    """Training time of a reused run, from its own log (steps x mean step time), if it logged one."""
    path = run / "metrics.jsonl"
    if not path.exists():
        return None
    timed = [line for line in map(json.loads, path.read_text().splitlines()) if "time/step_s" in line]
    return timed[-1]["step"] * timed[-1]["time/step_s"] if timed else None


def _curves(stages: Stages) -> dict[str, list[dict]]:
    """Real success at each learning-curve evaluation of every RL arm, with the imagined
    (judged) success beside it for the world-model arms; Dyna's at the end of each round."""
    curves = {}
    for spec in ARMS:
        if not spec.is_rl or not stages.done(f"arm_{spec.name}"):
            continue
        if spec.dyna:
            curves[spec.name] = [{"step": row["rl_steps"], "real": row["success"], "real_ci": [row["ci_low"], row["ci_high"]],
                                  "own": None} for row in _dyna_summary(stages)["rounds"]]
            continue
        summary = read_json(stages.path(f"arm_{spec.name}") / "summary.json")
        where = "own" if spec.env.real_sight else "real"
        curves[spec.name] = [{"step": point["step"], "real": point.get(f"eval/{where}_success"),
                              "real_ci": [point.get(f"eval/{where}_ci_low"), point.get(f"eval/{where}_ci_high")],
                              "own": point.get("eval/own_success")} for point in summary["curve"]]
    return curves


def _dyna_summary(stages: Stages) -> dict:
    return read_json(Path(stages.record("arm_dyna")["run"]) / "summary.json")


def _watch(stages: Stages) -> dict[str, list[dict]]:
    """The reward-hacking watch of each world-model arm: imagined verdicts replayed in the real
    world, by step (Dyna's steps counted over its rounds)."""
    watch = {}
    for name in WM_ARMS:
        if not stages.done(f"arm_{name}"):
            continue
        if arm(name).dyna:
            summary = _dyna_summary(stages)
            steps = summary["settings"]["rl"]["steps"]
            runs = [(Path(stages.record("arm_dyna")["run"]) / f"round_{row['round']}" / "rl", (row["round"] - 1) * steps)
                    for row in summary["rounds"] if row["round"]]
        else:
            runs = [(stages.path(f"arm_{name}"), 0)]
        watch[name] = [row for run, offset in runs for row in _watch_rows(run, offset)]
    return watch


def _watch_rows(run: Path, offset: int) -> list[dict]:
    rows = []
    for line in (run / "metrics.jsonl").read_text().splitlines():
        values = json.loads(line)
        if "eval/watch_real_success" in values:
            rows.append({"step": values["step"] + offset,
                         **{key.removeprefix("eval/watch_"): value for key, value in values.items()
                            if key.startswith("eval/watch_") and "interactions" not in key}})
    return rows


def _dyna_against_real_rl(stages: Stages, config: ExperimentConfig) -> dict | None:
    """Dyna's rounds beside the real-world RL arm's learning curve, both with the real interactions
    spent on training by then (the shape `gymnast dyna` reports in, for its table and plot)."""
    from gymnast.experiment.dyna import real_rl_curve

    if not (stages.done("arm_dyna") and stages.done("arm_rl_real")):
        return None
    dyna = _dyna_summary(stages)
    real = stages.path("arm_rl_real")
    curve = real_rl_curve(real, read_json(real / "summary.json")["curve"])
    keep = ("round", "rl_steps", "success", "ci_low", "ci_high", "episodes", "rollout_episodes", "rollout_successes",
            "judge_fpr_on_rollouts", "judge_heldout_real_fpr", "real_interactions", "measurement_real_interactions")
    return {"tasks": config.tasks, "eval_episodes_per_task": config.rl.eval_episodes,
            "rounds": [{key: row.get(key) for key in keep} for row in dyna["rounds"]], "real_rl": {"curve": curve}}


def _weak_tasks(arms: dict[str, dict], config: ExperimentConfig) -> dict | None:
    """Each arm's success pooled over the weak tasks this experiment has, with a Wilson interval
    (every task has the same number of evaluation episodes)."""
    from gymnast.eval.stats import wilson_interval

    tasks = config.weak_task_list
    if not tasks:
        return None
    episodes = config.eval_episodes * len(tasks)
    pooled = {}
    for name, row in arms.items():
        successes = round(sum(row["per_task"][task]["success"] for task in tasks) * config.eval_episodes)
        low, high = wilson_interval(successes, episodes)
        pooled[name] = {"success": successes / episodes, "ci_low": low, "ci_high": high, "episodes": episodes}
    return {"tasks": tasks, "arms": pooled}


def _equal_budget(stages: Stages) -> dict | None:
    """The three uses of one real budget (`gymnast.experiment.equal_budget`): each one's real
    success with its interval and the real interactions it spent on training (None: not run)."""
    from gymnast.experiment.equal_budget import EQUAL_BUDGET_ARMS

    if not all(stages.done(f"eval_equal_budget_{name}") for name in EQUAL_BUDGET_ARMS):
        return None
    rows = {}
    for name in EQUAL_BUDGET_ARMS:
        result, trained = stages.record(f"eval_equal_budget_{name}"), stages.record(f"equal_budget_{name}")
        rows[name] = {**_brief(result), "real_interactions": trained["real_interactions"],
                      "per_task": {task: v["success"] for task, v in result["per_task"].items()}}
    return rows


def _equal_budget_setup(stages: Stages, config: ExperimentConfig) -> dict | None:
    """How the equal budget was spent: the recorded rollouts and each arm's steps."""
    if not stages.done("equal_budget_real_grpo"):
        return None
    recorded = stages.record("equal_budget_rollouts")
    return {"rollouts_per_task": config.equal_budget.rollouts_per_task,
            "recorded": {key: recorded[key] for key in ("episodes", "successes", "real_interactions")},
            "real_grpo_steps": stages.record("equal_budget_real_grpo")["steps"], "imagined_rl_steps": config.rl.steps}


def build_summary(stages: Stages, config: ExperimentConfig, to_run: Sequence[str] = ()) -> dict:
    """summary.json's content, from the finished stages; `to_run`: the stages still to run, for a
    report of an experiment under way (its figures so far; the goals wait for every stage)."""
    # An experiment older than an arm (Dyna) reports without it until a rerun has trained it.
    arms = {spec.name: _arm_row(stages, spec.name, spec.title) for spec in ARMS if stages.done(f"eval_{spec.name}")}
    success = {name: row["success"] for name, row in arms.items()}
    worldgym = stages.record("worldgym") if stages.done("worldgym") else {"pearson": None, "spearman": None, "policies": None}
    judge = stages.record("judge")
    judge_metrics = judge.get("metrics") or _read_json(stages.path("judge") / "metrics.json")
    evaluated = [name for name in ROBUSTNESS_ARMS if all(stages.done(f"eval_{name}{suffix}") for suffix in
                                                         ("", *(f"_{p}" for p in PERTURBATIONS), "_heldout"))]
    robustness = {name: {"none": _brief(stages.record(f"eval_{name}")),
                         **{p: _brief(stages.record(f"eval_{name}_{p}")) for p in PERTURBATIONS}} for name in evaluated}
    language = {name: {"train": robustness[name]["none"], "heldout": _brief(stages.record(f"eval_{name}_heldout"))}
                for name in evaluated}
    # The SFT policy's judged imagination against the real world (None in experiments older than the stage).
    imagination = _without_bookkeeping(stages.record("imagination")) if stages.done("imagination") else None
    # Over every task and over the weak ones (an experiment older than the weak readout has only the first).
    signal = _without_bookkeeping(stages.record("signal")) if stages.done("signal") else None
    signal_weak = signal.pop("weak", None) if signal else None
    if signal and stages.done("signal_state"):  # the state model's reward on the same starts and rollouts
        state = stages.record("signal_state")
        signal["imagined_state"] = state["imagined"]
        if signal_weak and state.get("weak"):
            signal_weak["imagined_state"] = state["weak"]["imagined"]
    summary = {
        "tasks": config.tasks,
        "arms": arms,
        "wm_rl_over_sft": _ratio(success.get("rl_wm_judge"), success.get("sft")),
        "wm_rl_over_sim_rl": _ratio(success.get("rl_wm_judge"), success.get("rl_sim")),
        "wm_rl_verified_over_sft": _ratio(success.get("rl_wm_verified"), success.get("sft")),
        "wm_rl_verified_over_sim_rl": _ratio(success.get("rl_wm_verified"), success.get("rl_sim")),
        "worldgym_pearson": worldgym["pearson"],
        "worldgym_spearman": worldgym["spearman"],
        "worldgym": worldgym["policies"],
        "robustness": robustness,
        "language": language,
        "language_sentences": str(config.sentences) if config.sentences is not None else None,
        "curves": (curves := _curves(stages)),
        "equal_wall_clock": equal_wall_clock({spec.name: stages.path(f"arm_{spec.name}") for spec in ARMS
                                              if spec.is_rl and not spec.dyna and stages.done(f"arm_{spec.name}")},
                                             curves.get("rl_real", [])),
        "watch": (watch := _watch(stages)),
        "watch_false_success": {name: rows[-1].get("false_success") if rows else None for name, rows in watch.items()},
        "weak_tasks": (weak := _weak_tasks(arms, config)),
        "dyna_real_interactions": arms["dyna"]["real_interactions"] if "dyna" in arms else None,
        "real_rl_real_interactions": arms["rl_real"]["real_interactions"] if "rl_real" in arms else None,
        "dyna": _dyna_against_real_rl(stages, config),
        "equal_budget": (equal_budget := _equal_budget(stages)),
        "equal_budget_setup": _equal_budget_setup(stages, config),
        # Test-time practice on new scenes (None where the preset leaves it out, or the experiment predates it).
        "new_scenes": _without_bookkeeping(stages.record("new_scenes")) if stages.done("new_scenes") else None,
        "judge": {k: v for k, v in (judge_metrics or {}).items() if k.startswith(("real_", "imagined_"))},
        "judge_rollouts": judge.get("rollouts"),
        "world_model": _without_bookkeeping(stages.record("world_model_eval")) if stages.done("world_model_eval") else None,
        "imagination_agreement": imagination["agreement"] if imagination else None,
        "imagination": imagination,
        "signal": signal,
        "signal_weak": signal_weak,
        "dataset": _dataset_brief(stages, required=not to_run),
        "sft_demonstrations": _sft_demonstrations(stages.path("sft")),
        "rl_steps": config.rl.steps,
        "rollouts_per_step": config.rl.starts_per_step * config.rl.group_size,
        "eval_episodes_per_task": config.eval_episodes,
        "stage_wall_s": {path.stem: read_json(path).get("wall_s")
                         for path in sorted((stages.out / "stages").glob("*.json"))},
        "stages_to_run": list(to_run),
    }
    summary["goals"] = None if to_run else experiment_goals(arms, weak, worldgym["pearson"],
                                                            summary["watch_false_success"], equal_budget)
    return summary


def _dataset_brief(stages: Stages, required: bool = True) -> dict | None:
    """The collected dataset's episodes and real interactions: counted in it, or, in an exported
    experiment, which holds no dataset (experiment.export), as the summary written beside it said;
    None where neither is there and the report is of an experiment under way (not `required`)."""
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.data.lerobot_v3 import INFO_PATH

    path = stages.path("collect")
    if (path / INFO_PATH).is_file():
        dataset = EpisodeDataset(path)
        return {"episodes": len(dataset), "real_interactions": int(sum(dataset.lengths)), "path": str(dataset.root)}
    written = (_read_json(stages.out / "summary.json") or {}).get("dataset")
    if written and written.get("path") == str(path):
        return written
    if not required:
        return None
    raise FileNotFoundError(f"{path}: the experiment's dataset is not there and no summary.json of {stages.out} "
                            "counted it; record it again with the collect settings in its config.json")


def _sft_demonstrations(run: Path) -> dict | None:
    """How many expert demonstrations the SFT policy learned from, as its run saved them (a reused
    run's own: the regime is the policy's, not the preset's); None for a policy that saved none
    (a LeRobot checkpoint)."""
    saved = _read_json(run / "config.json") or {}
    if "demos" not in saved:
        return None
    return {"per_task": saved["sft"]["demos_per_task"], "episodes": len(saved["demos"])}


def _without_bookkeeping(record: dict) -> dict:
    return {key: value for key, value in record.items() if key not in BOOKKEEPING}


def _brief(record: dict) -> dict:
    return {key: record[key] for key in ("success", "ci_low", "ci_high", "episodes")}


def _read_json(path: Path) -> dict | None:
    return read_json(path) if path.exists() else None


def write_report(out: Path, stages: Stages, config: ExperimentConfig, to_run: Sequence[str] = ()) -> dict:
    """Writes summary.json, plots/ and report.md in `out`; returns the summary. With stages still
    `to_run` (an experiment under way, `gymnast experiment --report`): the figures so far, and no plots."""
    from gymnast.experiment.plots import plot_curves, plot_per_task, plot_worldgym
    from gymnast.experiment.report.text import partial_report_markdown, report_markdown

    summary = build_summary(stages, config, to_run)
    write_json(out / "summary.json", summary)
    if to_run:
        write_bytes(out / "report.md", partial_report_markdown(summary).encode())
        logger.info("report so far (%d stages still to run): %s", len(to_run), out / "report.md")
        return summary
    plots = {"per_task": plot_per_task(summary, out / "plots" / "per_task.png"),
             "curves": plot_curves(summary, out / "plots" / "learning_curves.png"),
             "worldgym": plot_worldgym(summary, out / "plots" / "worldgym.png")}
    if summary["dyna"]:
        from gymnast.experiment.dyna_report import plot_dyna

        plots["dyna"] = plot_dyna(summary["dyna"], out / "plots" / "dyna.png")
    markdown = report_markdown(summary, {name: path.relative_to(out).as_posix() for name, path in plots.items()})
    write_bytes(out / "report.md", markdown.encode())
    logger.info("report: %s", out / "report.md")
    return summary


def format_table(summary: dict) -> str:
    """The arms as aligned text (success, 95% CI, real interactions, wall time), then the result in
    sentences, each goal met, not met or "not significant at this size" as report.md says it."""
    from gymnast.experiment.report.text import verdict_lines

    rows = [("arm", "success", "95% CI", "real interactions", "wall time")]
    for row in summary["arms"].values():
        rows.append((row["title"], f"{row['success']:.1%}", f"[{row['ci_low']:.1%}, {row['ci_high']:.1%}]",
                     f"{row['real_interactions']:,}", wall_time(row)))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * width for width in widths))
    ratios = (f"world-model RL (judge) / SFT: {ratio(summary['wm_rl_over_sft'])}; "
              f"/ software-sim RL: {ratio(summary['wm_rl_over_sim_rl'])}; "
              f"WorldGym Pearson r: {number(summary['worldgym_pearson'])}, Spearman: {number(summary['worldgym_spearman'])}")
    return "\n".join([*lines, "", ratios, "", *(line.replace("**", "") for line in verdict_lines(summary))])
