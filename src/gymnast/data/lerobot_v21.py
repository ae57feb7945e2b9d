"""Reading LeRobot v2.0 / v2.1 datasets: one parquet file and one mp4 per episode.

Layout: ``meta/episodes.jsonl`` (one JSON object per episode: episode_index, tasks, length),
``meta/tasks.jsonl``, optional ``meta/episodes_stats.jsonl``, and files named by the templates in
``info.json``, e.g. ``data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet`` and
``videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4`` where
``episode_chunk = episode_index // chunks_size``.

Published datasets depart from it in ways whose meaning is clear, and these are read with a
deviation recorded (`gymnast.data.deviations`): templates of another version or none
(`gymnast.data.lerobot_paths`), no ``chunks_size`` (LeRobot's 1000), an episode list without
``tasks`` (each episode's ``task_index`` through ``tasks.jsonl``) or without ``length`` (its file's
rows), no episode list at all (the data files are listed), and an episode list longer than the
folder (a dataset cut to its first episodes: the episodes whose data files are there are read).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from gymnast.data.deviations import Deviations
from gymnast.data.lerobot_format import DatasetError, EpisodeRef, MissingFile, column_vector, read_parquet
from gymnast.data.lerobot_paths import V2_DATA_PATH, V2_VIDEO_PATH, PathTemplate, locate_episode_file
from gymnast.data.lerobot_v3 import DEFAULT_CHUNKS_SIZE, INFO_PATH, info_field

CODEBASE_VERSIONS = ("v2.0", "v2.1")
EPISODES_PATH = "meta/episodes.jsonl"
TASKS_PATH = "meta/tasks.jsonl"
_NAMES = ("episode_chunk", "episode_index", "video_key")


def episode_refs(root: Path, info: Mapping, image_key: str, notes: Deviations) -> list[EpisodeRef]:
    """Locate every episode of a v2.x dataset; ``image_key`` is the camera feature read.

    Raises:
        MissingFile: neither the episode list nor any data file is there.
        DatasetError: malformed metadata (the message names the file, the line and the field).
    """
    info_path = root / INFO_PATH
    fps = info_field(info, "fps", (int, float), info_path)
    chunks_size = info.get("chunks_size", None)
    if not isinstance(chunks_size, int) or isinstance(chunks_size, bool) or chunks_size <= 0:
        notes.add(info_path, "chunks_size", f"'chunks_size' is {chunks_size!r}",
                  f"LeRobot's default {DEFAULT_CHUNKS_SIZE} is used")
        chunks_size = DEFAULT_CHUNKS_SIZE
    data = PathTemplate.read(info, "data_path", V2_DATA_PATH, _NAMES, info_path, notes)
    is_video = info["features"][image_key].get("dtype") == "video"
    video = PathTemplate.read(info, "video_path", V2_VIDEO_PATH, _NAMES, info_path, notes) if is_video else None
    tasks = _read_tasks(root / TASKS_PATH, notes)
    refs = []
    for where, row in _episode_rows(root, data, chunks_size, notes):
        index = row.get("episode_index")
        if not isinstance(index, int) or isinstance(index, bool) or index < 0:
            raise DatasetError(f"{where}: field 'episode_index' must be an integer >= 0, got {index!r}")
        names = {"episode_chunk": index // chunks_size, "episode_index": index, "video_key": image_key}
        data_path = locate_episode_file(root, root / data.format(names), index, "data", "", notes)
        video_path = None
        if video is not None:
            video_path = locate_episode_file(root, root / video.format(names), index, "videos", image_key, notes)
        length = row.get("length")
        if length is None and data_path.is_file():
            length = _file_rows(data_path)
            notes.add(root / EPISODES_PATH, "length", "episodes have no 'length'", "their data files' rows are counted")
        if not isinstance(length, int) or isinstance(length, bool):
            raise DatasetError(f"{where}: field 'length' must be an integer, got {length!r}")
        task = _episode_task(row, where, data_path, tasks, notes)
        refs.append(EpisodeRef(index, length, task, data_path, None, video_path, (0.0, length / fps), row,
                               root / EPISODES_PATH))
    refs.sort(key=lambda ref: ref.index)
    indices = [ref.index for ref in refs]
    if len(set(indices)) < len(indices):
        raise DatasetError(f"{root / EPISODES_PATH}: an episode_index is listed twice")
    present = [ref for ref in refs if ref.data_path.is_file()]
    if present and len(present) < len(refs) and present == refs[: len(present)]:
        notes.add(root / EPISODES_PATH, "episodes", f"it lists {len(refs)} episodes; data files exist for the first "
                  f"{len(present)}", f"those {len(present)} are read (a dataset cut to its first episodes)")
        refs = present
    return refs


def _episode_rows(root: Path, data: PathTemplate, chunks_size: int, notes: Deviations) -> list[tuple[str, dict]]:
    """(where, row) for each episode of ``meta/episodes.jsonl``, or, without one, of each data file."""
    path = root / EPISODES_PATH
    if path.is_file():
        return [(f"{path}:{line}", row) for line, row in _read_jsonl(path)]
    files = sorted((root / "data").rglob("episode_*.parquet")) if (root / "data").is_dir() else []
    if not files:
        raise MissingFile(f"episode list not found: {path} (and no data/**/episode_*.parquet to list instead)")
    notes.add(path, "episodes", f"{EPISODES_PATH} is missing", "episodes listed from the data files' names and rows")
    rows = []
    for file in files:
        try:
            index = int(file.stem.removeprefix("episode_"))
        except ValueError:
            continue
        rows.append((str(file), {"episode_index": index}))
    return rows


def _episode_task(row: dict, where: str, data_path: Path, tasks: dict[int, str], notes: Deviations) -> str:
    """The episode's instruction: the first of its ``tasks``, else its rows' ``task_index`` in ``tasks.jsonl``."""
    listed = row.get("tasks")
    if isinstance(listed, str):
        listed = [listed]
    if isinstance(listed, list) and listed and all(isinstance(t, str) for t in listed):
        if len(listed) > 1:
            notes.add(where.rsplit(":", 1)[0], "tasks", f"episodes list several tasks (e.g. {listed[:3]})",
                      "the first is the episode's instruction")
        return listed[0]
    if listed is not None:
        raise DatasetError(f"{where}: field 'tasks' is {listed!r}, expected a list of strings")
    if len(tasks) == 1:
        notes.add(where.rsplit(":", 1)[0], "tasks", "episodes have no 'tasks'", f"the one task of {TASKS_PATH} is theirs")
        return next(iter(tasks.values()))
    if tasks and data_path.is_file():
        table = read_parquet(data_path, ["task_index"] if "task_index" in _file_columns(data_path) else [])
        if table.num_columns and table.num_rows:
            index = int(column_vector(table, "task_index", data_path, float)[0])
            if index in tasks:
                notes.add(where.rsplit(":", 1)[0], "tasks", "episodes have no 'tasks'",
                          f"each takes its first row's task_index in {TASKS_PATH}")
                return tasks[index]
    raise DatasetError(f"{where}: the episode has no task: give it a 'tasks' list of instructions, or give its rows "
                       f"a 'task_index' that {TASKS_PATH} names")


def _read_tasks(path: Path, notes: Deviations) -> dict[int, str]:
    """task_index -> task of ``meta/tasks.jsonl`` (empty without one)."""
    if not path.is_file():
        notes.add(path, "tasks", f"{TASKS_PATH} is missing", "tasks come from the episode list")
        return {}
    tasks = {}
    for line, row in _read_jsonl(path):
        index, task = row.get("task_index"), row.get("task")
        if not isinstance(index, int) or not isinstance(task, str):
            raise DatasetError(f"{path}:{line}: fields 'task_index' and 'task' must be an integer and a string, "
                               f"got {index!r}, {task!r}")
        tasks[index] = task
    return tasks


def _file_rows(path: Path) -> int:
    try:
        return pq.read_metadata(path).num_rows
    except (pa.ArrowException, OSError) as e:
        raise DatasetError(f"{path}: cannot read parquet file: {e}") from e


def _file_columns(path: Path) -> list[str]:
    try:
        return pq.read_schema(path).names
    except (pa.ArrowException, OSError) as e:
        raise DatasetError(f"{path}: cannot read parquet file: {e}") from e


def _read_jsonl(path: Path) -> list[tuple[int, dict]]:
    """(line number, object) for each non-empty line; errors name the file and line."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: cannot read: {e}") from e
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as e:
            raise DatasetError(f"{path}:{number}: not valid JSON: {e}") from e
        if not isinstance(row, dict):
            raise DatasetError(f"{path}:{number}: expected a JSON object")
        rows.append((number, row))
    return rows
