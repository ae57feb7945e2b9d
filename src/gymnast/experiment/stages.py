"""Stage bookkeeping: an experiment is a list of named stages, each done once.

A stage that finishes writes ``DIR/stages/<name>.json`` (atomically) with what it produced and how
long it took; a rerun reads that record instead of running the stage again. A stage interrupted
half-way has no record and runs again, and the trainers underneath continue from their own last
checkpoint, so an interruption costs at most one checkpoint interval.

A stage can also be *reused* from elsewhere (``--reuse world_model=runs/wm``): its record then
points at that directory and says it was not run here. The world model can also be one of one's
own (``--reuse world_model=python:MODULE:FACTORY[@ARG]`` or ``plugin:NAME[@ARG]``,
`gymnast.utils.plugins`), which every stage after it loads by that name. When another experiment ran that stage, the
record carries what that experiment measured of it (`measured_elsewhere`): a reused judge's real
rollouts are real interactions the experiment spent too.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from gymnast.data.lerobot_v3 import INFO_PATH
from gymnast.utils.atomic import read_json, write_json
from gymnast.utils.memory import release_freed_memory
from gymnast.utils.plugins import is_plugin

logger = logging.getLogger(__name__)

REUSABLE = ("collect", "sft", "world_model", "judge", "state_model")
"""Stages whose output another run can provide: a dataset or a trained model directory."""


class Stages:
    """Runs the stages of the experiment in `out`, skipping those already recorded.

    Args:
        out: the experiment directory.
        reuse: stage name -> an existing directory that stands for the stage's output.
    """

    def __init__(self, out: Path, reuse: dict[str, Path] | None = None) -> None:
        self.out = out
        self.reuse = dict(reuse or {})
        unknown = set(self.reuse) - set(REUSABLE)
        if unknown:
            raise ValueError(f"--reuse names unknown stages {sorted(unknown)}; reusable stages are {list(REUSABLE)}")
        for name, path in self.reuse.items():
            if name == "world_model" and is_plugin(path):
                continue  # its factory loads it
            if not Path(path).is_dir():
                raise FileNotFoundError(f"--reuse {name}={path}: no such directory")

    def record_path(self, name: str) -> Path:
        return self.out / "stages" / f"{name}.json"

    def done(self, name: str) -> bool:
        return self.record_path(name).exists()

    def record(self, name: str) -> dict:
        """A finished stage's record (KeyError-like FileNotFoundError if it has not run)."""
        path = self.record_path(name)
        if not path.exists():
            raise FileNotFoundError(f"stage {name!r} has not finished in {self.out} (no {path})")
        return read_json(path)

    def run(self, name: str, work: Callable[[], dict], output: Path | None = None) -> dict:
        """The stage's record: read back if it finished before, else `work()`'s, with ``wall_s``.

        `work` returns what the stage measured (JSON-ready). `output` is the stage's directory,
        which a reused stage replaces with the given one.
        """
        if self.done(name):
            record = self.record(name)
            if name in self.reuse and record.get("path") != str(self.reuse[name]):
                raise ValueError(f"stage {name!r} of {self.out} already finished with {record.get('path')}; "
                                 f"it cannot be reused from {self.reuse[name]} now (start a new experiment directory)")
            logger.info("stage %s: done before, skipped", name)
            return record
        if name in self.reuse:
            record = {"stage": name, "path": str(self.reuse[name]), "reused": True, "wall_s": None,
                      **measured_elsewhere(name, Path(self.reuse[name]))}
        else:
            logger.info("stage %s: running", name)
            began = time.perf_counter()
            record = {"stage": name, "path": str(output) if output else None, "reused": False, **work()}
            record["wall_s"] = record.get("wall_s", time.perf_counter() - began)
            # What the stage decoded stays in the heap, not returned, through every later stage: in the
            # two-camera headline the judge's training frames kept the process at 9.2 GB until its end.
            release_freed_memory()
        write_json(self.record_path(name), record)
        return record

    def pending(self, names: Sequence[str]) -> bool:
        """Whether any of the stages `names` is still to run."""
        return not all(self.done(name) for name in names)

    def restore_dataset(self, name: str, dataset: Path, record: Callable[[], dict], still_read: bool, what: str,
                        recorded: Callable[[dict], dict] = lambda record: record) -> None:
        """Makes whole the real rollouts that stage `name` recorded here into `dataset` while a stage
        still to run reads them (`still_read`: in this experiment, or in one that reuses this one's
        stage): `record()` again (the same scenes, seeds and settings; it skips the episodes already
        there) records them anew in a run copied without its datasets and finishes a recording that
        was interrupted. `what` names them in the log.

        `record()` returns what the recording holds (``episodes``, ``successes``), and `recorded`
        finds the same figures in the stage's record: a recording made again that differs from the
        first (on a CPU of another kind the same seeds can take other trajectories) is said in a
        warning, as the stages still to run learn from this one.
        """
        if not still_read or not self.done(name) or self.record(name)["reused"]:
            return
        if not (dataset / INFO_PATH).is_file():
            logger.warning("%s is missing: recording %s again, as a stage still to run reads them", dataset, what)
        now, first = record(), recorded(self.record(name))
        changed = [f"{key} {now.get(key)} (the stage's recording: {first.get(key)})"
                   for key in ("episodes", "successes") if now.get(key) != first.get(key)]
        if changed:
            logger.warning("%s in %s differ from what stage %s recorded: %s; the stages still to run learn from "
                           "these", what, dataset, name, ", ".join(changed))

    def path(self, name: str) -> Path:
        """Where a finished (or reused) stage's output lives."""
        return Path(self.record(name)["path"])


BOOKKEEPING = ("stage", "path", "reused", "wall_s")
"""The fields of a stage record that say how it was done, not what it measured."""


def measured_elsewhere(name: str, path: Path) -> dict:
    """What the experiment whose stage `name` made `path` recorded of it (its figures, as
    ``measured_in`` that experiment's directory and ``measured_wall_s`` the stage's time there);
    nothing when `path` is not another experiment's stage output."""
    source = path.parent / "stages" / f"{name}.json"
    if not source.is_file():
        return {}
    record = read_json(source)
    if Path(record.get("path") or "").resolve() != path.resolve():  # that experiment reused another directory
        return {}
    figures = {key: value for key, value in record.items() if key not in BOOKKEEPING}
    return {**figures, "measured_in": str(path.parent), "measured_wall_s": record.get("wall_s")}


def parse_reuse(items: list[str]) -> dict[str, Path]:
    """``["world_model=runs/wm", ...]`` -> {"world_model": Path("runs/wm"), ...}."""
    parsed = {}
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise ValueError(f"--reuse expects STAGE=DIR (e.g. world_model=runs/wm), got {item!r}")
        parsed[name.strip()] = Path(path.strip())
    return parsed
