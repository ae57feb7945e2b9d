"""LeRobot v3.0 layout: file paths, ``info.json``, the episode index and the task table.

v3.0 packs many episodes into each file. ``meta/episodes/chunk-XXX/file-XXX.parquet`` holds one row
per episode saying where its frames are: rows [dataset_from_index, dataset_to_index) of a data
file and [from_timestamp, to_timestamp) of a video file. ``meta/info.json`` counts the episodes;
rows beyond ``total_episodes`` belong to an unfinished write and are ignored.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from gymnast.data.deviations import Deviations
from gymnast.data.lerobot_format import (
    ACTION_NAMES,
    STATE_NAMES,
    DatasetError,
    EpisodeRef,
    MissingFile,
    check_info_columns,
    compatible_type,
    has_info_columns,
    read_parquet,
)
from gymnast.data.lerobot_paths import PathTemplate

CODEBASE_VERSION = "v3.0"
INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
TASKS_PATH = "meta/tasks.parquet"
EPISODES_DIR = "meta/episodes"
CHUNK_FILE = "chunk-{chunk_index:03d}/file-{file_index:03d}"
EPISODES_PATH = EPISODES_DIR + "/" + CHUNK_FILE + ".parquet"
DATA_PATH = "data/" + CHUNK_FILE + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE + ".mp4"
DEFAULT_CHUNKS_SIZE = 1000
DEFAULT_DATA_FILE_SIZE_IN_MB = 100
DEFAULT_VIDEO_FILE_SIZE_IN_MB = 500
_NAMES = ("chunk_index", "file_index", "video_key")

_INT, _FLOAT = pa.int64(), pa.float64()
INDEX_COLUMNS = {
    "episode_index": _INT,
    "length": _INT,
    "data/chunk_index": _INT,
    "data/file_index": _INT,
    "dataset_from_index": _INT,
    "dataset_to_index": _INT,
}


def video_columns(video_key: str) -> dict[str, pa.DataType]:
    """The episode-index columns locating an episode in the video files of one camera."""
    prefix = f"videos/{video_key}/"
    return {
        prefix + "chunk_index": _INT,
        prefix + "file_index": _INT,
        prefix + "from_timestamp": _FLOAT,
        prefix + "to_timestamp": _FLOAT,
    }


def load_info(root: Path) -> dict:
    """Read ``meta/info.json``; errors name the file."""
    path = root / INFO_PATH
    if not path.is_file():
        raise MissingFile(f"no LeRobot dataset at {root}: {path} not found")
    try:
        info = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: not valid JSON: {e}") from e
    if not isinstance(info, dict):
        raise DatasetError(f"{path}: expected a JSON object, got {type(info).__name__}")
    return info


def info_field(info: Mapping, name: str, kind: type | tuple[type, ...], path: Path) -> Any:
    """A required field of ``info.json`` with the expected Python type."""
    value = info.get(name)
    if not isinstance(value, kind) or isinstance(value, bool):  # bool is an int, never a count
        kinds = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
        raise DatasetError(f"{path}: field {name!r} is {value!r}, expected {'a number' if kinds == 'int or float' else kinds}")
    return value


def read_episode_rows(
    root: Path,
    info: Mapping,
    required: Mapping[str, pa.DataType] = INDEX_COLUMNS,
    keep: Callable[[str], bool] = lambda name: not name.startswith("stats/"),
    notes: Deviations | None = None,
) -> list[tuple[Path, dict]]:
    """The committed episodes' metadata rows, in episode order, each with the file it came from.

    Args:
        root: dataset directory.
        info: its ``info.json``.
        required: columns every episode-metadata file must have, with their types.
        keep: which columns to read (per-episode stats are skipped by default: they are large and
            only the writer's recovery needs them).
        notes: where a reader records deviations; given, episode rows for only the first of the
            ``total_episodes`` (a dataset cut to some of its episodes) are read with a note
            rather than refused (the writer, which restores commits, gives none).
    """
    total = info_field(info, "total_episodes", int, root / INFO_PATH)
    rows = []
    for path in sorted((root / EPISODES_DIR).glob("chunk-*/file-*.parquet")):
        schema = _read_schema(path)
        for name, kind in required.items():
            _check_column(schema, name, kind, path)
        if has_info_columns(schema.names):
            check_info_columns(schema, path)
        table = read_parquet(path, [n for n in schema.names if keep(n) or n == "episode_index"])
        for name in required:
            if name in table.column_names and table.column(name).null_count:
                raise DatasetError(f"{path}: field {name!r} has empty (null) values")
        rows += [(path, row) for row in table.to_pylist() if row["episode_index"] < total]
    rows.sort(key=lambda item: item[1]["episode_index"])
    found = [row["episode_index"] for _, row in rows]
    if notes is not None and found and found == list(range(len(found))) and len(found) < total:
        notes.add(root / EPISODES_DIR, "total_episodes", f"info.json lists {total} episodes, the episode metadata "
                  f"{len(found)}", f"those {len(found)} are read (a dataset cut to its first episodes)")
    elif found != list(range(total)):
        missing = sorted(set(range(total)) - set(found))[:5]
        raise DatasetError(
            f"{root / EPISODES_DIR}: info.json lists {total} episodes but the episode metadata has "
            f"{len(found)} rows below that index (missing e.g. {missing}, or duplicates); set info.json's "
            "'total_episodes' to the episodes there are"
        )
    return rows


def episode_refs(root: Path, info: Mapping, image_key: str, notes: Deviations) -> list[EpisodeRef]:
    """Locate every committed episode of a v3.0 dataset; ``image_key`` is the camera feature read."""
    info_path = root / INFO_PATH
    data_template = PathTemplate.read(info, "data_path", DATA_PATH, _NAMES, info_path, notes)
    is_video = info["features"][image_key].get("dtype") == "video"
    video_template = PathTemplate.read(info, "video_path", VIDEO_PATH, _NAMES, info_path, notes) if is_video else None
    required = INDEX_COLUMNS | (video_columns(image_key) if is_video else {})
    prefix = f"videos/{image_key}/"
    refs = []
    for path, row in read_episode_rows(root, info, required, notes=notes):
        index, tasks = row["episode_index"], row.get("tasks")
        if isinstance(tasks, str):
            tasks = [tasks]
        if not (isinstance(tasks, list) and tasks and all(isinstance(t, str) for t in tasks)):
            raise DatasetError(
                f"{path}: field 'tasks' of episode {index} is {tasks!r}, expected a list of strings"
            )
        if len(tasks) > 1:
            notes.add(path, "tasks", f"episodes list several tasks (e.g. {tasks[:3]})", "the first is the episode's instruction")
        names = {"chunk_index": row["data/chunk_index"], "file_index": row["data/file_index"], "video_key": image_key}
        data = data_template.format(names)
        video, span = None, (0.0, 0.0)
        if video_template is not None:
            names = {"chunk_index": row[prefix + "chunk_index"], "file_index": row[prefix + "file_index"],
                     "video_key": image_key}
            video = root / video_template.format(names)
            span = (row[prefix + "from_timestamp"], row[prefix + "to_timestamp"])
            if not 0 <= span[0] < span[1]:
                raise DatasetError(f"{path}: episode {index}'s {prefix}from_timestamp and to_timestamp are {span}, "
                                   "expected 0 <= from < to (seconds inside its video file)")
        rows = (row["dataset_from_index"], row["dataset_to_index"])
        refs.append(EpisodeRef(index, row["length"], tasks[0], root / data, rows, video, span, row, path))
    present = [ref for ref in refs if ref.data_path.is_file()]
    if present and len(present) < len(refs) and present == refs[: len(present)]:
        notes.add(root / EPISODES_DIR, "episodes", f"it lists {len(refs)} episodes; data files exist for the first "
                  f"{len(present)}", f"those {len(present)} are read (a dataset cut to its first episodes)")
        refs = present
    return refs


def build_features(shapes: Mapping[str, tuple[int, ...]], fps: int, videos: Mapping[str, Mapping]) -> dict:
    """``info.json`` features: each camera's video with its stream description, then every data column.

    Args:
        shapes: the shape of every feature (the vectors' and each camera's).
        fps: frames per second.
        videos: each camera feature (``observation.images.<camera>``), in camera order, to the
            stream description of its video.
    """

    def vector(name: str, names: list[str] | None) -> dict:
        size = shapes[name][0]
        return {
            "dtype": "float32",
            "shape": [size],
            "names": names if names and len(names) == size else None,
        }

    def scalar(dtype: str) -> dict:
        return {"dtype": dtype, "shape": [1], "names": None}

    features = {
        key: {
            "dtype": "video",
            "shape": list(shapes[key]),
            "names": ["height", "width", "channels"],
            "info": dict(video),
        }
        for key, video in videos.items()
    }
    features["observation.state"] = vector("observation.state", STATE_NAMES)
    if shapes["observation.environment_state"][0]:
        features["observation.environment_state"] = vector("observation.environment_state", None)
    features |= {
        "action": vector("action", ACTION_NAMES),
        "timestamp": scalar("float32"),
        "frame_index": scalar("int64"),
        "episode_index": scalar("int64"),
        "index": scalar("int64"),
        "task_index": scalar("int64"),
        "next.reward": scalar("float32"),
        "next.success": scalar("bool"),
        "next.done": scalar("bool"),
        "action_is_pad": scalar("bool"),
    }
    for name, feature in features.items():
        if name not in videos:
            feature["fps"] = fps  # LeRobot v3.0 gives every non-video feature its rate
    return features


def tasks_table(tasks: Mapping[str, int]) -> pa.Table:
    """``meta/tasks.parquet``: task strings and their ``task_index``.

    LeRobot reads this file with pandas and expects the task string as the DataFrame's index, so
    the table carries the pandas metadata that makes the ``task`` column the index.
    """
    table = pa.table(
        {
            "task_index": pa.array(list(tasks.values()), pa.int64()),
            "task": pa.array(list(tasks), pa.string()),
        }
    )
    pandas_metadata = {
        "index_columns": ["task"],
        "column_indexes": [
            {
                "name": None,
                "field_name": None,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": {"encoding": "UTF-8"},
            }
        ],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": "task",
                "field_name": "task",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    return table.replace_schema_metadata({"pandas": json.dumps(pandas_metadata)})


def read_tasks(path: Path) -> dict[str, int]:
    """Task string -> task_index, from a ``tasks.parquet`` written by gymnast or by LeRobot."""
    table = read_parquet(path)
    name = next((n for n in ("task", "__index_level_0__") if n in table.column_names), None)
    if name is None or "task_index" not in table.column_names:
        raise DatasetError(f"{path}: fields 'task' and 'task_index' are needed, found {table.column_names}")
    return dict(zip(table.column(name).to_pylist(), table.column("task_index").to_pylist(), strict=True))


def _read_schema(path: Path) -> pa.Schema:
    try:
        return pq.read_schema(path)
    except (pa.ArrowException, OSError, ValueError) as e:
        raise DatasetError(f"{path}: cannot read parquet file: {e}") from e


def _check_column(schema: pa.Schema, name: str, kind: pa.DataType, path: Path) -> None:
    if name not in schema.names:
        raise DatasetError(f"{path}: field {name!r} is missing")
    if not compatible_type(schema.field(name).type, kind):
        raise DatasetError(f"{path}: field {name!r} has type {schema.field(name).type}, expected {kind}")
