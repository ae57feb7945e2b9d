"""The `gymnast` command: one subcommand per job, each a thin call into the library."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import tyro

import gymnast  # noqa: F401  (sets MUJOCO_GL before anything imports mujoco)
from gymnast.cli.data import collect, contact_sheet, gap_report, inspect, stills, tasks
from gymnast.cli.judge import calibrate_judge, eval_judge, serve_judge, train_judge
from gymnast.cli.measure import imagination, practice_summary, rl_signal, worldgym
from gymnast.cli.policy import check_policy, evaluate_command, sft
from gymnast.cli.practice import dyna, experiment, ladder, rl
from gymnast.cli.world_model import check_wm, eval_wm, make_ensemble, object_fidelity, train_state, train_wm
from gymnast.utils.memory import reuse_large_blocks


def doctor() -> None:
    """Check that this machine can render the simulator headlessly, and say what to install if not."""
    from gymnast.utils.device import bf16_status
    from gymnast.utils.disk_cache import CACHE_ENV, cache_root
    from gymnast.utils.system import check_rendering

    ok, message = check_rendering()
    print(message)
    print(bf16_status())
    root = cache_root()
    print(f"cache: {root if root else f'off ({CACHE_ENV})'} (sentence embeddings shared by every process)")
    if not ok:
        raise SystemExit(1)


def export(run: Path, out: Path, exclude: tuple[str, ...] = (), datasets: bool = False,
           optimizer: bool = False) -> None:
    """Copy a run to share or commit: its results, records and newest models, without its bulk.

    Left out: the datasets it recorded (directories with meta/info.json), every checkpoint but the
    one each trainer's ``last`` names, and the optimizers' states. OUT appears only once complete.
    A finished experiment copied back to where it ran reruns with every stage skipped.

    Args:
        run: the run directory (an experiment, an RL, SFT, world-model or judge run).
        out: the new directory for the copy (must not exist).
        exclude: glob patterns of paths relative to RUN to leave out too (e.g. 'new_scenes/*/checkpoints').
        datasets: keep the recorded datasets.
        optimizer: keep the optimizers' states, so that an unfinished trainer can --resume exactly.
    """
    from gymnast.experiment.export import export_run

    print(export_run(run, out, exclude=exclude, datasets=datasets, optimizer=optimizer).summary())


COMMANDS = {
    "collect": collect,
    "inspect": inspect,
    "sft": sft,
    "eval": evaluate_command,
    "check-policy": check_policy,
    "train-wm": train_wm,
    "train-state": train_state,
    "eval-wm": eval_wm,
    "check-wm": check_wm,
    "make-ensemble": make_ensemble,
    "object-fidelity": object_fidelity,
    "train-judge": train_judge,
    "calibrate-judge": calibrate_judge,
    "serve-judge": serve_judge,
    "eval-judge": eval_judge,
    "rl": rl,
    "experiment": experiment,
    "dyna": dyna,
    "ladder": ladder,
    "imagination": imagination,
    "rl-signal": rl_signal,
    "practice-summary": practice_summary,
    "worldgym": worldgym,
    "contact-sheet": contact_sheet,
    "stills": stills,
    "gap-report": gap_report,
    "tasks": tasks,
    "export": export,
    "doctor": doctor,
}


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `gymnast` console script."""
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("OpenGL").setLevel(logging.WARNING)
    try:
        reuse_large_blocks()  # every subcommand runs torch on the CPU somewhere (utils.memory)
        tyro.extras.subcommand_cli_from_dict(COMMANDS, args=sys.argv[1:] if argv is None else argv,
                                             prog="gymnast", description=__doc__)
    except (ValueError, FileNotFoundError, FileExistsError) as error:
        # Bad input is the user's to fix: say what is wrong without a traceback.
        print(f"gymnast: error: {error}", file=sys.stderr)
        raise SystemExit(2) from None
