"""Where a dataset departs from the LeRobot specification, and what reading it decides to do about it.

Published LeRobot datasets follow the specification loosely: path templates of another version,
wall-clock timestamps, missing columns and meta files, shapes under ``info``, grayscale cameras,
raw joint units. The readers take every such dataset whose meaning is clear and record here what
they assumed, one `Deviation` per kind (repeats in other files are counted, not repeated), so that
`gymnast inspect` can say it in one line each and `gymnast inspect --check` can list them all with
the decision each leads to. What cannot be read is a `gymnast.data.lerobot_format.DatasetError`
whose message names the file, the field and the fix.

    notes = Deviations()
    notes.add(path, "timestamp", "timestamps are wall-clock (from 1.7e+09 s)", "frames placed by frame_index at 20 fps")
    for deviation in notes: print(deviation)
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from gymnast.data.lerobot_format import is_list

logger = logging.getLogger(__name__)

_SPEC_COLUMNS = ("timestamp", "frame_index", "episode_index", "index", "task_index")
"""The bookkeeping columns LeRobot writes in every data file."""
_VECTOR_DTYPES = ("float16", "float32", "float64")


@dataclass(frozen=True)
class Deviation:
    """One way a dataset departs from the specification.

    Attributes:
        path: the file (or folder) where it was found first.
        field: the field, column or key concerned.
        found: what the dataset does.
        decision: what gymnast does about it (or, where `blocking`, what would fix it).
        blocking: training cannot proceed.
        count: in how many files it was found.
    """

    path: str
    field: str
    found: str
    decision: str
    blocking: bool = False
    count: int = 1

    def __str__(self) -> str:
        more = f" (and {self.count - 1} more files)" if self.count > 1 else ""
        return f"{self.path}{more}: {self.found}; {self.decision}"


class Deviations:
    """The deviations met while reading a dataset, each kind once, in the order met."""

    def __init__(self) -> None:
        self._found: dict[tuple[str, str], Deviation] = {}

    def add(self, path: str | Path, field: str, found: str, decision: str, blocking: bool = False) -> None:
        """Record a deviation; one of a kind already recorded (same field and decision) is counted.

        The first of each kind is logged as a warning, so that training commands say what they assumed.
        """
        key = (field, decision)
        known = self._found.get(key)
        if known is not None:
            if str(path) != known.path:
                self._found[key] = Deviation(known.path, field, known.found, decision, known.blocking, known.count + 1)
            return
        self._found[key] = Deviation(str(path), field, found, decision, blocking)
        logger.warning("%s", self._found[key])

    def merge(self, other: Deviations) -> None:
        """Record every deviation of `other` here (its counts kept), without logging them again."""
        for deviation in other:
            key = (deviation.field, deviation.decision)
            known = self._found.get(key)
            count = deviation.count + (known.count if known is not None else 0)
            self._found[key] = Deviation(**{**(known or deviation).__dict__, "count": count})

    def __iter__(self) -> Iterator[Deviation]:
        return iter(self._found.values())

    def __len__(self) -> int:
        return len(self._found)

    @property
    def blocking(self) -> bool:
        """Whether any deviation keeps training from proceeding."""
        return any(d.blocking for d in self)


def check_rows(table: pa.Table, path: Path, fps: float, features: dict, notes: Deviations) -> None:
    """Note what an episode's (or a file's) data rows do otherwise than LeRobot writes them.

    Checked: the bookkeeping columns present, timestamps against ``frame_index / fps`` (which the
    readers never need: frames are placed by their position in the episode), columns that
    ``info.json`` does not declare, and vectors stored as nested lists.
    """
    names = table.column_names
    for name in _SPEC_COLUMNS:
        if name not in names:
            notes.add(path, name, f"column {name!r} is missing", _MISSING_DECISIONS[name])
    undeclared = [name for name in names if name not in features]
    if undeclared:
        notes.add(path, "columns", f"columns not declared in info.json's features: {', '.join(undeclared[:5])}",
                  "ignored")
    for name in names:
        kind = table.schema.field(name).type
        if is_list(kind) and is_list(kind.value_type):
            notes.add(path, name, f"{name!r} is stored as nested lists ({kind})", "flattened to one vector per row")
        declared = features.get(name)
        if (not is_list(kind) and isinstance(declared, dict) and declared.get("dtype") in _VECTOR_DTYPES
                and name not in _SPEC_COLUMNS and not name.startswith("next.") and name != "action_is_pad"):
            notes.add(path, name, f"{name!r} is stored as plain numbers, not lists", "read as vectors of width 1")
    if "timestamp" in names and table.num_rows > 1 and fps > 0:
        _check_timestamps(table, path, fps, notes)


def _check_timestamps(table: pa.Table, path: Path, fps: float, notes: Deviations) -> None:
    column = table.column("timestamp")
    if not (pa.types.is_floating(column.type) or pa.types.is_integer(column.type)):
        notes.add(path, "timestamp", f"timestamps are of type {column.type}", f"ignored: frames placed by frame_index at {fps:g} fps")
        return
    stamps = column.to_numpy(zero_copy_only=False).astype(np.float64)
    if not np.isfinite(stamps).all():
        notes.add(path, "timestamp", "timestamps are not all finite", f"ignored: frames placed by frame_index at {fps:g} fps")
        return
    steps = np.diff(stamps)
    if "episode_index" in table.column_names:  # a file of several episodes starts each one at 0 again
        episodes = table.column("episode_index").to_numpy(zero_copy_only=False)
        steps = steps[episodes[1:] == episodes[:-1]]
        if not len(steps):
            return
    regular = np.abs(steps - 1 / fps).max() <= 0.5 / fps
    if stamps[0] > 1e6:
        notes.add(path, "timestamp", f"timestamps are wall-clock (from {stamps[0]:.4g} s)",
                  f"frames placed by frame_index at {fps:g} fps")
    elif not regular:
        notes.add(path, "timestamp", f"timestamps step by {np.median(steps):.4g} s, not 1/fps = {1 / fps:.4g} s",
                  f"frames placed by frame_index at {fps:g} fps")


_MISSING_DECISIONS = {
    "timestamp": "not needed: frames placed by their position in the episode",
    "frame_index": "not needed: rows taken in file order",
    "episode_index": "not needed where each file holds one episode",
    "index": "episodes located by episode_index (v3.0) or by file (v2.x)",
    "task_index": "tasks taken from the episode list",
}
