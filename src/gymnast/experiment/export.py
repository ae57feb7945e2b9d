"""A run copied to share or commit: what its results and models need, without what is bulk.

Any run directory (an experiment, an RL or SFT run, a world model, a judge) holds three kinds of
bulk that nothing reading its results needs: the datasets it recorded (real rollouts as LeRobot
video), every checkpoint but the newest of each trainer, and the optimizers' states, which only a
trainer that goes on training reads. `export_run` copies everything else, byte for byte, into a
directory that appears whole or not at all, and says what it left out.

A finished experiment exported this way and copied back to where it ran reruns with every stage
skipped; the stages that read a dataset again record it anew first (`Stages.restore_dataset`).
A trainer whose run was exported without its optimizer state loads for evaluation and as a start,
but cannot `--resume` exactly (it says so: `utils.checkpoint.load_checkpoint`).
"""

from __future__ import annotations

import fnmatch
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from gymnast.data.lerobot_v3 import INFO_PATH
from gymnast.utils.atomic import atomic_directory
from gymnast.utils.checkpoint import LAST, OPTIMIZER_FILE


@dataclass
class LeftOut:
    """What one kind of bulk the export left out: how many files and how many bytes."""

    files: int = 0
    bytes: int = 0

    def add(self, path: Path) -> None:
        for file in _files_under(path):
            self.files += 1
            self.bytes += file.stat().st_size


@dataclass
class Export:
    """What `export_run` copied and what it left out, by kind."""

    destination: Path
    files: int = 0
    bytes: int = 0
    left_out: dict[str, LeftOut] = field(default_factory=lambda: {kind: LeftOut() for kind in LEFT_OUT_KINDS})

    def summary(self) -> str:
        lines = [f"{self.destination}: {self.files} files, {_size(self.bytes)}"]
        for kind, left in self.left_out.items():
            if left.files:
                lines.append(f"  left out {LEFT_OUT_KINDS[kind]}: {left.files} files, {_size(left.bytes)}")
        return "\n".join(lines)


LEFT_OUT_KINDS = {
    "datasets": "datasets (directories with meta/info.json)",
    "checkpoints": "checkpoints older than each trainer's last",
    "optimizer": "optimizer states",
    "excluded": "paths matching --exclude",
}


def export_run(run: Path, destination: Path, exclude: tuple[str, ...] = (), datasets: bool = False,
               optimizer: bool = False) -> Export:
    """Copies `run` to `destination` (which must not exist) without its bulk.

    Args:
        run: the run directory.
        destination: where the copy goes; it appears only once complete.
        exclude: glob patterns matched against paths relative to `run` (``new_scenes/*/checkpoints``);
            a matching directory is left out whole.
        datasets: keep the datasets too.
        optimizer: keep the optimizers' states too (so unfinished trainers can `--resume` exactly).

    Raises:
        FileNotFoundError: `run` is not a directory.
        FileExistsError: `destination` exists already.
    """
    run, destination = Path(run), Path(destination)
    if not run.is_dir():
        raise FileNotFoundError(f"{run}: no such run directory to export")
    if destination.exists():
        raise FileExistsError(f"{destination} exists already; export into a new directory")
    if destination.resolve().is_relative_to(run.resolve()):
        raise ValueError(f"{destination} is inside {run}, the run it would copy")
    export = Export(destination)

    def copy_tree(source: Path, target: Path, relative: Path) -> None:
        """Copies directory `source` (at `relative` in the run) into `target`, leaving out the bulk."""
        target.mkdir(exist_ok=True)
        kept_checkpoint = _kept_checkpoint(source) if source.name == "checkpoints" else None
        for entry in sorted(source.iterdir()):
            inside = relative / entry.name
            if any(fnmatch.fnmatch(inside.as_posix(), pattern) for pattern in exclude):
                export.left_out["excluded"].add(entry)
            elif entry.is_dir() and not entry.is_symlink():
                if not datasets and (entry / INFO_PATH).is_file():
                    export.left_out["datasets"].add(entry)
                elif kept_checkpoint is not None and entry.name != kept_checkpoint:
                    export.left_out["checkpoints"].add(entry)
                else:
                    copy_tree(entry, target / entry.name, inside)
            elif not optimizer and entry.name == OPTIMIZER_FILE:
                export.left_out["optimizer"].add(entry)
            else:
                shutil.copy2(entry, target / entry.name, follow_symlinks=False)
                export.files += 1
                export.bytes += entry.lstat().st_size

    with atomic_directory(destination) as staging:
        copy_tree(run, staging, Path("."))
    return export


def _kept_checkpoint(checkpoints: Path) -> str | None:
    """The step directory a trainer's ``checkpoints/`` keeps: the one ``last`` names (None: no
    ``last`` there, so every entry is kept, as it is not a trainer's)."""
    last = checkpoints / LAST
    return last.read_text().strip() if last.is_file() else None


def _files_under(path: Path):
    if path.is_file() or path.is_symlink():
        yield path
        return
    for root, _, names in os.walk(path):
        for name in names:
            file = Path(root) / name
            if not file.is_symlink():
                yield file


def _size(count: int) -> str:
    return f"{count / 1e6:.1f} MB"
