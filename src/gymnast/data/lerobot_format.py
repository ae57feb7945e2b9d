"""The LeRobot dataset format as gymnast uses it: names, per-frame columns, statistics, episode assembly.

Shared by the v3.0 writer (`gymnast.data.lerobot_writer`) and the v3.0 / v2.1 readers
(`gymnast.data.lerobot`). ``docs/dataset_format.md`` describes the layout on disk.

Legend: L rows (frames) of one episode, T = L - 1 steps (actions), S state size, E environment-state
size, A action dimensions, H/W image height/width, K episodes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from gymnast.data.schema import EXTERNAL, Episode, EpisodeColumns, EpisodeInfo

GYMNAST_PREFIX = "gymnast/"
KEY_COLUMN = "gymnast/key"
PSNR_COLUMN = "gymnast/video_psnr_db"
"""Per episode: the worst (minimum) PSNR in dB of its decoded frames against the raw frames."""

_FIELDS = dataclasses.fields(EpisodeInfo)
_PY_TYPES = {"str": str, "bool": bool, "float": float, "int": int}
_ARROW_TYPES = {"str": pa.string(), "bool": pa.bool_(), "float": pa.float64(), "int": pa.int64()}
INFO_COLUMNS: dict[str, pa.DataType] = {
    f"{GYMNAST_PREFIX}{f.name}": _ARROW_TYPES[str(f.type)] for f in _FIELDS
}
"""One episodes-metadata column per `EpisodeInfo` field, e.g. ``gymnast/behaviour``."""

STATE_NAMES = ["hand_x", "hand_y", "hand_z", "gripper_opening"]
ACTION_NAMES = ["dx", "dy", "dz", "gripper_effort"]


class DatasetError(ValueError):
    """A dataset file is unreadable or malformed; the message names the file, the field and what would fix it."""


class MissingFile(DatasetError, FileNotFoundError):
    """A file the dataset's metadata points to is not there; the message names it."""


@dataclass(frozen=True)
class FeatureKeys:
    """The features read as a robot's actions and states; the defaults are LeRobot's names."""

    action_key: str = "action"
    """Feature of the robot's actions, a float vector per frame (e.g. actions)."""
    state_key: str = "observation.state"
    """Feature of the robot's own state, a float vector per frame (e.g. state); a dataset without the
    default one has states of width 0."""

    @property
    def reads_default_state(self) -> bool:
        """Whether the states come from LeRobot's ``observation.state``, which a dataset may lack."""
        return self.state_key == FeatureKeys.state_key


CAMERA_PREFIX = "observation.images."


def image_key(camera: str) -> str:
    """The LeRobot feature name of a camera, e.g. ``front`` -> ``observation.images.front``."""
    return f"{CAMERA_PREFIX}{camera}"


@dataclass(frozen=True)
class EpisodeRef:
    """Where one episode lives on disk; enough to load it without reading anything else.

    Attributes:
        index: the episode's ``episode_index``.
        length: number of rows L (frames) of the episode.
        task: the LeRobot task string (the language instruction).
        data_path: parquet file holding the episode's rows.
        rows: [from, to) range of the global ``index`` column inside ``data_path``; None when the
            file holds this episode only (v2.1).
        video_path: mp4 holding the episode's frames, or None when images are stored in the rows.
        video_span: [from, to) timestamps in seconds of the episode inside ``video_path``.
        columns: the episode's metadata row (``gymnast/...`` columns among others).
        meta_path: the metadata file the episode was listed in, for error messages.
    """

    index: int
    length: int
    task: str
    data_path: Path
    rows: tuple[int, int] | None
    video_path: Path | None
    video_span: tuple[float, float]
    columns: Mapping[str, Any]
    meta_path: Path


def read_parquet(path: Path, columns: Sequence[str] | None = None) -> pa.Table:
    """Read a parquet file; a missing or unreadable file raises an error naming it."""
    if not path.is_file():
        raise MissingFile(f"parquet file not found: {path}")
    try:
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError, ValueError) as e:
        raise DatasetError(f"{path}: cannot read parquet file: {e}") from e


def require_columns(table: pa.Table, names: Sequence[str], path: Path) -> None:
    """Raise naming the file and the first missing column."""
    for name in names:
        if name not in table.column_names:
            raise DatasetError(f"{path}: field {name!r} is missing (columns: {table.column_names})")


def column_matrix(table: pa.Table, name: str, path: Path) -> np.ndarray:
    """A vector column as an (L, D) float32 array: lists of numbers, nested lists of numbers
    (flattened, row by row) or, for D = 1, plain numbers."""
    require_columns(table, [name], path)
    column = table.column(name).combine_chunks()
    if not is_list(column.type):
        if not (pa.types.is_floating(column.type) or pa.types.is_integer(column.type)):
            raise DatasetError(f"{path}: field {name!r} has type {column.type}, expected a list of numbers")
        return column.to_numpy(zero_copy_only=False).astype(np.float32).reshape(-1, 1)
    values = column
    while is_list(values.type):
        if values.null_count:
            raise DatasetError(f"{path}: field {name!r} has empty (null) rows")
        values = values.flatten()
    if not compatible_type(values.type, pa.float64()):
        raise DatasetError(f"{path}: field {name!r} has type {column.type}, expected a list of numbers")
    values = values.to_numpy(zero_copy_only=False).astype(np.float32)
    if len(column) == 0:
        return values.reshape(0, 0)
    if len(values) % len(column):
        raise DatasetError(f"{path}: field {name!r} has rows of different lengths")
    return values.reshape(len(column), -1)


def column_vector(table: pa.Table, name: str, path: Path, dtype: type) -> np.ndarray:
    """A scalar column as an (L,) array; also accepts LeRobot's one-element lists."""
    require_columns(table, [name], path)
    kind = table.schema.field(name).type
    if is_list(kind):
        kind, values = kind.value_type, table.column(name).combine_chunks().flatten()
    else:
        values = table.column(name)
    if not compatible_type(kind, pa.bool_() if dtype is bool else pa.float64()):
        raise DatasetError(f"{path}: field {name!r} has type {kind}, expected {dtype.__name__}")
    if values.null_count:
        raise DatasetError(f"{path}: field {name!r} has {values.null_count} empty (null) values")
    array = values.to_numpy(zero_copy_only=False).astype(dtype)
    if len(array) != table.num_rows:
        raise DatasetError(f"{path}: field {name!r} has {len(array)} values for {table.num_rows} rows")
    return array


def vector_array(matrix: np.ndarray) -> pa.Array:
    """(L, D) numbers -> a fixed-size-list column, as LeRobot writes vector features."""
    flat = pa.array(np.ascontiguousarray(matrix).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, matrix.shape[1])


def frame_columns(episode: Episode, episode_index: int, first_index: int, task_index: int, fps: int) -> dict:
    """The L = T + 1 data rows of an episode (the last row's action is zero padding)."""
    n_rows = episode.length + 1
    pad = np.zeros(n_rows, dtype=bool)
    pad[-1] = True
    actions = np.concatenate([episode.actions, np.zeros((1, episode.actions.shape[1]))]).astype(np.float32)
    # The padded row has no action, hence no reward; its success is the last step's (what the
    # final frame shows), and it is done like the step before it.
    rewards = np.append(episode.rewards, 0.0).astype(np.float32)
    successes = np.append(episode.successes, episode.successes[-1]).astype(bool)
    frame_index = np.arange(n_rows, dtype=np.int64)
    columns = {"observation.state": episode.states.astype(np.float32)}
    if episode.env_states.shape[1]:
        columns["observation.environment_state"] = episode.env_states.astype(np.float32)
    columns |= {
        "action": actions,
        "timestamp": (frame_index / fps).astype(np.float32),
        "frame_index": frame_index,
        "episode_index": np.full(n_rows, episode_index, dtype=np.int64),
        "index": first_index + frame_index,
        "task_index": np.full(n_rows, task_index, dtype=np.int64),
        "next.reward": rewards,
        "next.success": successes,
        "next.done": frame_index >= episode.length - 1,
        "action_is_pad": pad,
    }
    return columns


def to_arrow(columns: Mapping[str, np.ndarray]) -> dict[str, pa.Array]:
    """Numpy columns -> arrow columns (matrices become fixed-size lists)."""
    return {k: vector_array(v) if v.ndim == 2 else pa.array(v) for k, v in columns.items()}


def feature_stats(values: np.ndarray) -> dict[str, np.ndarray]:
    """min/max/mean/std/count over rows of an (L,) or (L, D) array; vectors come out (1,) or (D,)."""
    values = values.astype(np.float64).reshape(len(values), -1)
    return {
        "min": values.min(axis=0),
        "max": values.max(axis=0),
        "mean": values.mean(axis=0),
        "std": values.std(axis=0),
        "count": np.array([len(values)]),
    }


def image_stats(frames: np.ndarray) -> dict[str, np.ndarray]:
    """Per-channel stats of (N, H, W, 3) uint8 frames in [0, 1], shaped (3, 1, 1) like LeRobot's."""
    stats = feature_stats(frames.reshape(-1, 3) / 255.0)
    stats = {k: v.reshape(3, 1, 1) for k, v in stats.items() if k != "count"}
    return stats | {"count": np.array([len(frames)])}  # LeRobot counts images, not pixels


def episode_stats(columns: Mapping[str, np.ndarray], videos: Mapping[str, np.ndarray]) -> dict:
    """Stats of every numeric feature of one episode, plus each camera's per-channel stats.

    Padded actions are left out of the action stats: they are not actions, and zeros would pull
    the normalisation towards 0.

    Args:
        columns: the episode's data columns (`frame_columns`).
        videos: each camera feature to its (L, H, W, 3) uint8 frames.
    """
    stats = {}
    for name, values in columns.items():
        if name == "action":
            values = values[~columns["action_is_pad"]]
        stats[name] = feature_stats(values)
    for key, frames in videos.items():
        stats[key] = image_stats(frames)
    return stats


def aggregate_stats(stats_list: Sequence[Mapping[str, Mapping[str, Any]]]) -> dict:
    """Combine per-episode (or per-dataset) stats: exact pooled mean and standard deviation."""
    out = {}
    for name in dict.fromkeys(k for stats in stats_list for k in stats):
        parts = [
            {k: np.asarray(v, dtype=np.float64) for k, v in s[name].items()} for s in stats_list if name in s
        ]
        counts = np.array([p["count"].reshape(-1)[0] for p in parts])  # (K,)
        means = np.stack([p["mean"] for p in parts])  # (K, *shape)
        weights = (counts / counts.sum()).reshape(-1, *[1] * (means.ndim - 1))
        mean = (weights * means).sum(axis=0)
        stds = np.stack([p["std"] for p in parts])
        variance = (weights * (stds**2 + (means - mean) ** 2)).sum(axis=0)
        out[name] = {
            "min": np.min([p["min"] for p in parts], axis=0),
            "max": np.max([p["max"] for p in parts], axis=0),
            "mean": mean,
            "std": np.sqrt(variance),
            "count": np.array([int(counts.sum())]),
        }
    return out


def stats_to_json(stats: Mapping[str, Mapping[str, np.ndarray]]) -> dict:
    """Stats with numpy values -> nested lists (``count`` stays integer)."""
    return {
        name: {
            k: (np.asarray(v).astype(np.int64) if k == "count" else np.asarray(v)).tolist()
            for k, v in s.items()
        }
        for name, s in stats.items()
    }


def flatten_stats(stats: Mapping[str, Mapping[str, np.ndarray]]) -> dict:
    """``{feature: {stat: value}}`` -> LeRobot's ``stats/<feature>/<stat>`` episode columns."""
    return {f"stats/{name}/{k}": v for name, s in stats_to_json(stats).items() for k, v in s.items()}


def unflatten_stats(row: Mapping[str, Any]) -> dict:
    """``stats/<feature>/<stat>`` episode columns -> ``{feature: {stat: value}}``."""
    stats: dict = {}
    for name, value in row.items():
        if name.startswith("stats/"):
            feature, stat = name.removeprefix("stats/").rsplit("/", 1)
            stats.setdefault(feature, {})[stat] = value
    return stats


def info_columns(info: EpisodeInfo) -> dict[str, Any]:
    """The ``gymnast/...`` metadata columns of an episode (one per `EpisodeInfo` field, plus its key)."""
    # Coerced to the column types, so that every file has the same schema (noise=0 is a float).
    values = {
        name: _PY_TYPES[str(f.type)](getattr(info, f.name))
        for f, name in zip(_FIELDS, INFO_COLUMNS, strict=True)
    }
    return values | {KEY_COLUMN: info.key}


def has_info_columns(names: Sequence[str]) -> bool:
    """Whether episode metadata was written by gymnast (it has ``gymnast/...`` columns)."""
    return any(name.startswith(GYMNAST_PREFIX) for name in names)


def check_info_columns(schema: pa.Schema, path: Path) -> None:
    """Every `EpisodeInfo` column must be present with a compatible type."""
    for name, kind in INFO_COLUMNS.items():
        if name not in schema.names:
            raise DatasetError(f"{path}: field {name!r} is missing")
        if not compatible_type(schema.field(name).type, kind):
            raise DatasetError(f"{path}: field {name!r} has type {schema.field(name).type}, expected {kind}")


def is_list(kind: pa.DataType) -> bool:
    return pa.types.is_list(kind) or pa.types.is_fixed_size_list(kind) or pa.types.is_large_list(kind)


def compatible_type(actual: pa.DataType, expected: pa.DataType) -> bool:
    """Whether values of arrow type ``actual`` can be read as ``expected`` without loss of meaning."""
    if pa.types.is_floating(expected):
        return pa.types.is_floating(actual) or pa.types.is_integer(actual)
    if pa.types.is_integer(expected):
        return pa.types.is_integer(actual)
    if pa.types.is_string(expected):
        return pa.types.is_string(actual) or pa.types.is_large_string(actual)
    return pa.types.is_boolean(actual) or pa.types.is_integer(actual)  # a flag may be stored as 0/1


def episode_info(ref: EpisodeRef, successes: np.ndarray | None) -> EpisodeInfo:
    """The episode's facts: from ``gymnast/...`` columns, or defaults for datasets made elsewhere.

    Defaults: task and instruction are the LeRobot task string, behaviour ``expert``, noise 0,
    seed = the episode index, env_variant ``external``, success = any ``next.success`` if
    recorded, else True. A seed names a scene, and the held-out split is by scene: a recorded
    episode is a scene of its own (its initial state is its own), so each may be held out alone.
    """
    if has_info_columns(list(ref.columns)):
        values = {name.removeprefix(GYMNAST_PREFIX): ref.columns[name] for name in INFO_COLUMNS}
        try:
            return EpisodeInfo(**values)
        except (TypeError, ValueError) as e:
            raise DatasetError(f"{ref.meta_path}: episode {ref.index}: {e}") from e
    success = bool(successes.any()) if successes is not None else True
    return EpisodeInfo(ref.task, ref.task, success, "expert", 0.0, ref.index, EXTERNAL)


def episode_columns(ref: EpisodeRef, rows: pa.Table, keys: FeatureKeys = FeatureKeys()) -> EpisodeColumns:
    """An episode's vectors and facts from its L data rows (L - 1 steps); `keys` names the action
    and state columns.

    Rows written by gymnast end with one padded action (``action_is_pad``); rows from elsewhere
    pair every frame with an action, and the last action is dropped because the frame it leads
    to was not recorded. Missing optional fields become zeros (rewards; states and environment
    states of width 0: a state key asked for is checked against ``info.json`` before); missing ``next.success`` marks only the last step successful.
    """
    path, n_rows = ref.data_path, rows.num_rows
    if n_rows < 2:
        raise DatasetError(f"{path}: episode {ref.index} has {n_rows} rows, at least 2 are needed")
    n_steps, names = n_rows - 1, rows.column_names
    if "action_is_pad" in names:
        pad = column_vector(rows, "action_is_pad", path, bool)
        if pad[:-1].any() or not pad[-1]:
            raise DatasetError(
                f"{path}: field 'action_is_pad' of episode {ref.index} must mark only the last row"
            )
    if keys.state_key in names:
        states = column_matrix(rows, keys.state_key, path)
    else:
        states = np.zeros((n_rows, 0), np.float32)
    actions = column_matrix(rows, keys.action_key, path)[:n_steps]
    if "observation.environment_state" in names:
        env_states = column_matrix(rows, "observation.environment_state", path)
    else:
        env_states = np.zeros((n_rows, 0), np.float32)
    if "next.reward" in names:
        rewards = column_vector(rows, "next.reward", path, np.float32)[:n_steps]
    else:
        rewards = np.zeros(n_steps, np.float32)
    flags = column_vector(rows, "next.success", path, bool) if "next.success" in names else None
    # Without success flags the episode is taken to be a demonstration that ends in success.
    successes = flags[:n_steps] if flags is not None else np.arange(n_steps) == n_steps - 1
    return EpisodeColumns(states, env_states, actions, rewards, successes, episode_info(ref, flags))


def assemble_episode(
    ref: EpisodeRef, rows: pa.Table, frames: np.ndarray, views: Mapping[str, np.ndarray] | None = None,
    keys: FeatureKeys = FeatureKeys(),
) -> Episode:
    """Build an `Episode` from its L data rows (`episode_columns`) and their L frames (and every
    camera's, `views`, the primary's being `frames`: `Episode.views`)."""
    columns = episode_columns(ref, rows, keys)
    try:
        return Episode(frames, columns.states, columns.env_states, columns.actions, columns.rewards,
                       columns.successes, columns.info, dict(views or {}))
    except ValueError as e:  # shapes that disagree between fields
        raise DatasetError(f"{ref.data_path}: episode {ref.index}: {e}") from e
