"""Where an experiment stands, read from its directory without running anything (`gymnast
experiment --out RUN --status`): which stages finished and how long each took, which one is under
way and how far its trainer got (its newest checkpoint), and which are still to run.

A full headline runs for hours over several sittings; a rerun skips what finished and continues the
stage under way from its trainer's last checkpoint, so this is what a rerun will do next.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from gymnast.experiment.arms import ARMS, PERTURBATIONS, ROBUSTNESS_ARMS
from gymnast.experiment.config import ExperimentConfig
from gymnast.experiment.equal_budget import EQUAL_BUDGET_ARMS
from gymnast.experiment.pipeline import earlier_sft_checkpoints, saved_experiment_config
from gymnast.experiment.stages import Stages
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import LAST

MODELS = ("collect", "sft", "world_model", "judge", "state_model", "world_model_eval")
MEASUREMENTS = ("imagination", "signal", "signal_state")


def planned_stages(config: ExperimentConfig, sft_checkpoints: Sequence[str] = ()) -> list[str]:
    """Every stage `gymnast.experiment.pipeline.run_experiment` runs for `config`, in its order, with
    the evaluations of the SFT run's earlier checkpoints that WorldGym measures (`sft_checkpoints`,
    by name: `earlier_sft_checkpoints`; known once the SFT stage has run)."""
    names = [*MODELS, *MEASUREMENTS, *(f"arm_{arm.name}" for arm in ARMS[1:])]
    equal_budget = [f"equal_budget_{name}" for name in EQUAL_BUDGET_ARMS] if config.equal_budget.rollouts_per_task else []
    if equal_budget:
        names += ["equal_budget_rollouts", *equal_budget]
    if config.new_scenes.scenes_per_task:
        names.append("new_scenes")
    names += [f"eval_{arm.name}" for arm in ARMS] + [f"eval_{name}" for name in equal_budget]
    for name in ROBUSTNESS_ARMS:
        names += [*(f"eval_{name}_{perturb}" for perturb in PERTURBATIONS), f"eval_{name}_heldout"]
    return [*names, *(f"eval_{name}" for name in sft_checkpoints), "worldgym"]


def experiment_plan(out: Path, config: ExperimentConfig) -> list[str]:
    """`planned_stages` of the experiment in `out`, with its SFT run's earlier checkpoints once its
    SFT stage has run."""
    stages = Stages(out)
    sft = Path(stages.record("sft")["path"]) if stages.done("sft") else None
    return planned_stages(config, list(earlier_sft_checkpoints(sft)) if sft is not None else ())


@dataclass(frozen=True)
class StageStatus:
    """One stage: ``done``, ``under way`` (the first unfinished one, where a rerun goes on) or ``to run``.

    Attributes:
        wall_s: a finished stage's wall time (None when it was reused, or ran before times were kept).
        reused: the directory a reused stage stands for.
        checkpoint: the stage under way's newest trainer checkpoint, if it has one.
        step: that checkpoint's step, and `steps` the number its trainer runs to (when it says).
    """

    name: str
    state: str
    wall_s: float | None = None
    reused: str | None = None
    checkpoint: Path | None = None
    step: int | None = None
    steps: int | None = None


def experiment_status(out: Path, config: ExperimentConfig) -> list[StageStatus]:
    """The planned stages of the experiment in `out` (run with `config`), then any recorded stage
    the plan does not name (a run of another version)."""
    stages, rows, first_open = Stages(out), [], True
    planned = experiment_plan(out, config)
    for name in planned:
        if stages.done(name):
            record = stages.record(name)
            rows.append(StageStatus(name, "done", record.get("wall_s"), record.get("path") if record.get("reused") else None))
        elif first_open:
            first_open = False
            rows.append(StageStatus(name, "under way", **_trainer_progress(out, name)))
        else:
            rows.append(StageStatus(name, "to run"))
    recorded = sorted(path.stem for path in (out / "stages").glob("*.json"))
    return rows + [StageStatus(name, "done", stages.record(name).get("wall_s")) for name in recorded if name not in planned]


def report_so_far(out: Path) -> dict:
    """Writes the report of the experiment in `out` from the stages finished (`gymnast experiment
    --report`), naming those still to run; runs nothing. Returns the summary.

    Raises:
        FileNotFoundError: `out` holds no experiment.
    """
    from gymnast.experiment.report.write import write_report

    if not (out / "config.json").is_file():
        raise FileNotFoundError(f"--report: {out} holds no experiment (no config.json there)")
    config = saved_experiment_config(out)
    to_run = [row.name for row in experiment_status(out, config) if row.state != "done"]
    return write_report(out, Stages(out), config, to_run)


def _trainer_progress(out: Path, name: str) -> dict:
    """The newest checkpoint under the stage's directory (an arm's run, Dyna's rounds, a model),
    its step and the steps its run is set to; empty when nothing was saved yet."""
    work = out / "arms" / name.removeprefix("arm_") if name.startswith("arm_") else \
        out / name.replace("equal_budget_", "equal_budget/", 1)
    pointers = sorted(work.glob(f"**/checkpoints/{LAST}"), key=lambda path: path.stat().st_mtime) if work.is_dir() else []
    if not pointers:
        return {}
    checkpoint = pointers[-1].parent / pointers[-1].read_text().strip()
    trainer = read_json(checkpoint / "trainer.json")
    return {"checkpoint": checkpoint, "step": trainer.get("step"), "steps": _steps(checkpoint.parent.parent)}


def _steps(run: Path) -> int | None:
    """The steps a trainer's run is set to, from its saved settings (an RL run's ``rl``, a trainer's ``train``)."""
    path = run / "config.json"
    if not path.exists():
        return None
    settings = read_json(path)
    for section in ("rl", "train"):
        if isinstance(settings.get(section), dict) and "steps" in settings[section]:
            return settings[section]["steps"]
    return None


def format_status(out: Path, rows: list[StageStatus]) -> str:
    """The stages as aligned lines under a one-line summary."""
    done = [row for row in rows if row.state == "done"]
    hours = sum(row.wall_s or 0.0 for row in done) / 3600
    lines = [f"{out}: {len(done)} of {len(rows)} stages finished ({hours:.1f} h of stages run here), "
             f"{sum(row.state != 'done' for row in rows)} still to finish"]
    width = max(len(row.name) for row in rows)
    for row in rows:
        lines.append(f"  {row.state:<9}  {row.name:<{width}}  {_detail(row)}".rstrip())
    return "\n".join(lines)


def _detail(row: StageStatus) -> str:
    if row.reused:
        return f"reused: {row.reused}"
    if row.state == "done":
        return "-" if row.wall_s is None else f"{row.wall_s / 60:.1f} min"
    if row.checkpoint is not None:
        of = f" of {row.steps}" if row.steps is not None else ""
        return f"checkpoint at step {row.step}{of} ({row.checkpoint}); a rerun goes on from there"
    return "a rerun starts it" if row.state == "under way" else ""
