"""A dataset's action statistics: what the models' action normalisation is computed from.

LeRobot keeps per-feature min/max/mean/std in ``meta/stats.json`` and saves the ones a policy
was trained with alongside its weights; gymnast does the same for the action feature (``action``
unless `FeatureKeys.action_key` names another). The statistics come from ``meta/stats.json`` when
the dataset has them, else from the action column of every data file. Both the world model (its action input) and the policies (the tokenizer's and
the flow's ranges) use the min/max range, which maps Meta-World's actions, already in [-1, 1],
onto themselves.

Legend: A action dimensions, L rows.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from gymnast.data.lerobot_format import (DatasetError, FeatureKeys, MissingFile, aggregate_stats, column_matrix,
                                         column_vector, read_parquet)

STATS_PATH = "meta/stats.json"
_NAMES = ("min", "max", "mean", "std")


@dataclass(frozen=True)
class ActionStats:
    """Per-dimension statistics of a dataset's actions.

    Attributes:
        min, max, mean, std: (A,) each.
        count: actions they were computed over (0 when the dataset's stats file did not say).
    """

    min: tuple[float, ...]
    max: tuple[float, ...]
    mean: tuple[float, ...]
    std: tuple[float, ...]
    count: int = 0

    @property
    def dim(self) -> int:
        """Action dimensions A."""
        return len(self.min)

    def action_range(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(low, high) per dimension: min and max, except that a dimension that never changes
        (min == max) gets [value - 1, value + 1], so that the range is never empty."""
        low = tuple(lo if hi > lo else lo - 1.0 for lo, hi in zip(self.min, self.max))
        high = tuple(hi if hi > lo else hi + 1.0 for lo, hi in zip(self.min, self.max))
        return low, high

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def merge(cls, parts: Sequence[ActionStats]) -> ActionStats:
        """The statistics of several datasets' actions together (pooled mean and deviation).

        Raises:
            ValueError: the parts have different action dimensions.
        """
        if len({part.dim for part in parts}) > 1:
            raise ValueError(f"datasets with different action dimensions cannot train one model: {[p.dim for p in parts]}")
        if len(parts) == 1:
            return parts[0]
        pooled = aggregate_stats([{"action": {**{k: np.array(getattr(p, k)) for k in _NAMES},
                                              "count": np.array([max(p.count, 1)])}} for p in parts])["action"]
        return _from_arrays(pooled, sum(part.count for part in parts))


def read_action_stats(root: Path, dim: int, data_paths: Iterable[Path], key: str = FeatureKeys.action_key) -> ActionStats:
    """The action statistics of the dataset at `root` with `dim`-wide actions in feature `key`.

    From ``meta/stats.json`` when it has the `key` feature, else computed from the `key` column of
    `data_paths` (rows gymnast marks ``action_is_pad`` are not actions and are left out).

    Raises:
        MissingFile: a data file is missing.
        DatasetError: the stats file or a data file lacks the field or has the wrong width; the
            message names the file and the field.
    """
    path = root / STATS_PATH
    if path.is_file():
        try:
            saved = json.loads(path.read_text()).get(key)
        except (json.JSONDecodeError, UnicodeDecodeError, AttributeError) as e:
            raise DatasetError(f"{path}: not a JSON object of features: {e}") from e
        if saved is not None:
            return _from_saved(saved, dim, path, key)
    parts = []
    for data_path in dict.fromkeys(data_paths):
        table = read_parquet(data_path, [n for n in (key, "action_is_pad") if n in _columns(data_path)])
        actions = column_matrix(table, key, data_path)  # (L, A)
        if actions.shape[1] != dim:
            raise DatasetError(f"{data_path}: field {key!r} has {actions.shape[1]} values per row, "
                               f"info.json's {key!r} feature says {dim}")
        if "action_is_pad" in table.column_names:
            actions = actions[~column_vector(table, "action_is_pad", data_path, bool)]
        parts.append(actions)
    actions = np.concatenate(parts).astype(np.float64)
    if not len(actions):
        raise DatasetError(f"{root}: the data files hold no actions")
    values = {"min": actions.min(0), "max": actions.max(0), "mean": actions.mean(0), "std": actions.std(0)}
    return _from_arrays(values, len(actions))


def _columns(path: Path) -> list[str]:
    if not path.is_file():
        raise MissingFile(f"parquet file not found: {path}")
    try:
        return pq.read_schema(path).names
    except (pa.ArrowException, OSError) as e:
        raise DatasetError(f"{path}: cannot read parquet file: {e}") from e


def _from_saved(saved: object, dim: int, path: Path, key: str) -> ActionStats:
    """`ActionStats` from the `key` entry of a stats file, each statistic checked for width."""
    if not isinstance(saved, dict):
        raise DatasetError(f"{path}: field {key!r} is {type(saved).__name__}, expected an object of statistics")
    values = {}
    for name in _NAMES:
        value = np.asarray(saved.get(name), dtype=object)
        try:
            value = value.astype(np.float64).reshape(-1)
        except (TypeError, ValueError):
            value = np.zeros(0)
        if value.shape != (dim,) or not np.isfinite(value).all():
            raise DatasetError(f"{path}: field '{key}.{name}' is {saved.get(name)!r}, expected {dim} finite numbers "
                               f"(the width of info.json's {key!r} feature)")
        values[name] = value
    count = np.asarray(saved.get("count", [0])).reshape(-1)
    return _from_arrays(values, int(count[0]) if len(count) else 0)


def _from_arrays(values: dict, count: int) -> ActionStats:
    return ActionStats(*(tuple(float(v) for v in np.asarray(values[name]).reshape(-1)) for name in _NAMES), count=int(count))
