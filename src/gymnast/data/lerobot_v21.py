"""Reading LeRobot v2.0 / v2.1 datasets: one parquet file and one mp4 per episode.

Layout: ``meta/episodes.jsonl`` (one JSON object per episode: episode_index, tasks, length),
``meta/tasks.jsonl``, optional ``meta/episodes_stats.jsonl``, and files named by the templates in
``info.json``, e.g. ``data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet`` and
``videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4`` where
``episode_chunk = episode_index // chunks_size``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

from gymnast.data.lerobot_format import DatasetError, EpisodeRef
from gymnast.data.lerobot_v3 import INFO_PATH, info_field

CODEBASE_VERSIONS = ("v2.0", "v2.1")
EPISODES_PATH = "meta/episodes.jsonl"


def episode_refs(root: Path, info: Mapping, image_key: str) -> list[EpisodeRef]:
    """Locate every episode of a v2.x dataset; ``image_key`` is the camera feature read."""
    info_path = root / INFO_PATH
    fps = info_field(info, "fps", (int, float), info_path)
    chunks_size = info_field(info, "chunks_size", int, info_path)
    data_template = info_field(info, "data_path", str, info_path)
    is_video = info["features"][image_key].get("dtype") == "video"
    video_template = info_field(info, "video_path", str, info_path) if is_video else None
    refs = []
    for line, row in _read_jsonl(root / EPISODES_PATH):
        where = f"{root / EPISODES_PATH}:{line}"
        index, length, tasks = row.get("episode_index"), row.get("length"), row.get("tasks")
        if not isinstance(index, int) or not isinstance(length, int):
            raise DatasetError(
                f"{where}: fields 'episode_index' and 'length' must be integers, got {index!r}, {length!r}"
            )
        if not (isinstance(tasks, list) and tasks and all(isinstance(t, str) for t in tasks)):
            raise DatasetError(f"{where}: field 'tasks' is {tasks!r}, expected a list of strings")
        names = {"episode_chunk": index // chunks_size, "episode_index": index}
        refs.append(
            EpisodeRef(
                index=index,
                length=length,
                task=tasks[0],
                data_path=root / data_template.format(**names),
                rows=None,
                video_path=None
                if video_template is None
                else root / video_template.format(video_key=image_key, **names),
                video_span=(0.0, length / fps),
                columns=row,
                meta_path=root / EPISODES_PATH,
            )
        )
    refs.sort(key=lambda ref: ref.index)
    if [ref.index for ref in refs] != list(range(len(refs))):
        raise DatasetError(f"{root / EPISODES_PATH}: episode indices are not 0..{len(refs) - 1}")
    return refs


def _read_jsonl(path: Path) -> list[tuple[int, dict]]:
    """(line number, object) for each non-empty line; errors name the file and line."""
    if not path.is_file():
        raise FileNotFoundError(f"episode list not found: {path}")
    rows = []
    for number, text in enumerate(path.read_text().splitlines(), start=1):
        if not text.strip():
            continue
        try:
            row = json.loads(text)
        except json.JSONDecodeError as e:
            raise DatasetError(f"{path}:{number}: not valid JSON: {e}") from e
        if not isinstance(row, dict):
            raise DatasetError(f"{path}:{number}: expected a JSON object")
        rows.append((number, row))
    return rows
