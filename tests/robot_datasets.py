"""LeRobot datasets of other robots, written by hand as LeRobot writes them (no gymnast columns).

`write_robot_dataset` makes v2.1 (one parquet and one mp4 per episode) or v3.0 (every episode in
one data file and one video per camera) datasets with any action width, frame size, frame rate and
cameras, for the tests that check a user's own robot goes through every command.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from gymnast.utils.video import DEFAULT_CODEC, VideoCodec, encode_video

TASKS = ("pick up the red cube", "put the cube in the bowl")


def robot_frames(n: int, height: int, width: int, seed: int = 0) -> np.ndarray:
    """(n, height, width, 3) uint8: a shaded background and a disc that moves, like a camera's view."""
    yy, xx = np.mgrid[0:height, 0:width] / max(height, width)
    background = np.stack([0.3 + 0.4 * xx, 0.4 + 0.3 * yy, 0.5 + 0.2 * xx * yy], axis=-1)
    frames = []
    for t in range(n):
        cx, cy = 0.4 + 0.2 * np.cos(t / 4 + seed), 0.35 + 0.15 * np.sin(t / 3 + seed)
        disc = np.clip((0.12 - np.hypot(xx - cx, yy - cy)) * max(height, width) / 1.5, 0, 1)[..., None]
        frames.append(background * (1 - disc) + np.array([0.85, 0.2, 0.1]) * disc)
    return (np.stack(frames) * 255).round().astype(np.uint8)


def write_robot_dataset(
    root: Path,
    *,
    version: str = "v2.1",
    action_dim: int = 7,
    height: int = 120,
    width: int = 160,
    fps: int = 10,
    episodes: int = 4,
    steps: int = 12,
    cameras: Sequence[str] = ("front",),
    without_video: Sequence[str] = (),
    short_video: bool = False,
    action_scale: float = 1.0,
    codec: VideoCodec = DEFAULT_CODEC,
) -> Path:
    """Write a dataset of `episodes` episodes of `steps` + 1 rows each and return `root`.

    Args:
        root: dataset directory (created).
        version: ``v2.1`` or ``v3.0`` (``v2.0`` writes the v2.1 layout with that version).
        action_dim: width of the ``action`` feature.
        height, width: frame size of every camera.
        fps: frames per second of the rows and the videos.
        episodes: episodes, alternating between two tasks.
        steps: actions per episode (each episode has steps + 1 rows and frames).
        cameras: camera names, each declared as a video feature in ``info.json``.
        without_video: cameras declared but whose video files were never written.
        short_video: the last episode's video of each camera lacks its last frame (a recorder
            that wrote one frame fewer than it logged).
        action_scale: actions are drawn uniformly from [-scale, scale] (a robot's own units).
        codec: how the videos are encoded (``info.json`` says ``h264`` whatever it is, as some recorders do).
    """
    rng = np.random.default_rng(0)
    rows = steps + 1
    v3 = version == "v3.0"
    features = {
        f"observation.images.{camera}": {
            "dtype": "video", "shape": [height, width, 3], "names": ["height", "width", "channels"],
            "info": {"video.fps": fps, "video.height": height, "video.width": width, "video.codec": "h264"},
        }
        for camera in cameras
    }
    features |= {
        "observation.state": {"dtype": "float32", "shape": [action_dim], "names": None},
        "action": {"dtype": "float32", "shape": [action_dim], "names": None},
        **{k: {"dtype": "int64", "shape": [1], "names": None} for k in ("frame_index", "episode_index", "index", "task_index")},
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
        "next.success": {"dtype": "bool", "shape": [1], "names": None},
    }
    info = {
        "codebase_version": version, "robot_type": f"robot_{action_dim}dof", "total_episodes": episodes,
        "total_frames": episodes * rows, "total_tasks": len(TASKS), "fps": fps,
        "splits": {"train": f"0:{episodes}"}, "features": features, "chunks_size": 1000,
        "data_path": ("data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet" if v3
                      else "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"),
        "video_path": ("videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4" if v3
                       else "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"),
    }
    (root / "meta").mkdir(parents=True)
    (root / "meta/info.json").write_text(json.dumps(info, indent=2))
    tables, videos = [], {camera: [] for camera in cameras}
    for e in range(episodes):
        columns = {
            "observation.state": rng.normal(size=(rows, action_dim)).astype(np.float32),
            "action": (action_scale * rng.uniform(-1, 1, (rows, action_dim))).astype(np.float32),
            "timestamp": np.arange(rows, dtype=np.float32) / fps,
            "frame_index": np.arange(rows),
            "episode_index": np.full(rows, e),
            "index": e * rows + np.arange(rows),
            "task_index": np.full(rows, e % len(TASKS)),
            "next.success": np.arange(rows) >= rows - 4,  # the task is done for the last few steps
        }
        tables.append(pa.table({k: pa.array(list(v)) if v.ndim == 2 else pa.array(v) for k, v in columns.items()}))
        for c, camera in enumerate(cameras):
            frames = robot_frames(rows, height, width, seed=e + 10 * c)
            videos[camera].append(frames[:-1] if short_video and e == episodes - 1 else frames)
    tasks = [TASKS[e % len(TASKS)] for e in range(episodes)]
    if v3:
        _write_v3_files(root, tables, videos, tasks, without_video, fps, codec)
    else:
        _write_v21_files(root, tables, videos, tasks, without_video, fps, codec)
    return root


def _write_v21_files(root: Path, tables: list[pa.Table], videos: dict, tasks: list[str],
                     without_video: Sequence[str], fps: int, codec: VideoCodec) -> None:
    (root / "meta/tasks.jsonl").write_text("".join(json.dumps({"task_index": i, "task": t}) + "\n"
                                                   for i, t in enumerate(TASKS)))
    lines = []
    for e, table in enumerate(tables):
        (root / "data/chunk-000").mkdir(parents=True, exist_ok=True)
        pq.write_table(table, root / f"data/chunk-000/episode_{e:06d}.parquet")
        for camera, frames in videos.items():
            if camera not in without_video:
                encode_video(root / f"videos/chunk-000/observation.images.{camera}/episode_{e:06d}.mp4", frames[e], fps, codec)
        lines.append(json.dumps({"episode_index": e, "tasks": [tasks[e]], "length": table.num_rows}))
    (root / "meta/episodes.jsonl").write_text("\n".join(lines) + "\n")


def _write_v3_files(root: Path, tables: list[pa.Table], videos: dict, tasks: list[str],
                    without_video: Sequence[str], fps: int, codec: VideoCodec) -> None:
    (root / "data/chunk-000").mkdir(parents=True)
    pq.write_table(pa.concat_tables(tables), root / "data/chunk-000/file-000.parquet")
    task_table = pa.table({"task_index": pa.array(range(len(TASKS)), pa.int64()), "task": list(TASKS)})
    pq.write_table(task_table, root / "meta/tasks.parquet")
    meta: dict[str, list] = {"episode_index": [], "tasks": [], "length": [], "data/chunk_index": [],
                             "data/file_index": [], "dataset_from_index": [], "dataset_to_index": []}
    first = 0
    for e, table in enumerate(tables):
        for name, value in (("episode_index", e), ("tasks", [tasks[e]]), ("length", table.num_rows),
                            ("data/chunk_index", 0), ("data/file_index", 0), ("dataset_from_index", first),
                            ("dataset_to_index", first + table.num_rows)):
            meta[name].append(value)
        first += table.num_rows
    for camera, episodes in videos.items():
        prefix = f"videos/observation.images.{camera}/"
        if camera not in without_video:
            encode_video(root / f"{prefix}chunk-000/file-000.mp4", np.concatenate(episodes), fps, codec,
                         keyframes=np.cumsum([0] + [len(f) for f in episodes[:-1]]))
        starts = np.cumsum([0] + [t.num_rows for t in tables[:-1]]) / fps
        meta[prefix + "chunk_index"] = [0] * len(tables)
        meta[prefix + "file_index"] = [0] * len(tables)
        meta[prefix + "from_timestamp"] = starts.tolist()
        meta[prefix + "to_timestamp"] = (starts + np.array([t.num_rows for t in tables]) / fps).tolist()
    (root / "meta/episodes/chunk-000").mkdir(parents=True)
    pq.write_table(pa.table(meta), root / "meta/episodes/chunk-000/file-000.parquet")
