"""A corpus of small LeRobot datasets, each departing from the specification the way a published one does.

Every entry starts from a dataset of another robot written as LeRobot writes it
(`robot_datasets.write_robot_dataset`: 4 episodes of 12 steps, 7-D actions, 24x32 frames) and
changes one thing, or, for ``published_bimanual``, the many things a real two-camera dataset does
at once. `CORPUS` maps each name to its builder and to what reading it must give: ``None`` where its
meaning is clear (it is read, with the deviation recorded), else a piece of the one-line error.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from PIL import Image
from robot_datasets import robot_frames, write_robot_dataset

from gymnast.utils.video import VideoCodec, decode_video, encode_video

SIZE = dict(episodes=4, steps=12, height=24, width=32)
ROWS = SIZE["steps"] + 1
V21_VIDEO = "videos/chunk-000/observation.images.front/episode_{:06d}.mp4"
V21_DATA = "data/chunk-000/episode_{:06d}.parquet"


def _info(root: Path, change: Callable[[dict], None]) -> None:
    path = root / "meta/info.json"
    info = json.loads(path.read_text())
    change(info)
    path.write_text(json.dumps(info))


def _episodes(root: Path, change: Callable[[dict], dict | None]) -> None:
    """Rewrite each line of a v2.x ``episodes.jsonl`` (a line changed to None is dropped)."""
    path = root / "meta/episodes.jsonl"
    rows = [change(json.loads(line)) for line in path.read_text().splitlines() if line.strip()]
    path.write_text("".join(json.dumps(row) + "\n" for row in rows if row is not None))


def _tables(root: Path, change: Callable[[pa.Table], pa.Table]) -> None:
    for path in sorted((root / "data").rglob("*.parquet")):
        pq.write_table(change(pq.read_table(path)), path)


def _videos(root: Path, change: Callable[[np.ndarray], np.ndarray], episodes=None, codec=None) -> None:
    """Re-encode v2.x episode videos of the front camera with their frames changed."""
    for e in range(SIZE["episodes"]) if episodes is None else episodes:
        path = root / V21_VIDEO.format(e)
        frames = change(decode_video(path))
        path.unlink()
        encode_video(path, frames, 10, *([codec] if codec else []))


def _set_column(table: pa.Table, name: str, values) -> pa.Table:
    return table.set_column(table.column_names.index(name), name, values)


def _png(frame: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(frame).save(buffer, format="PNG")
    return buffer.getvalue()


def _images_in_rows(root: Path, key: str, convert: Callable[[np.ndarray], np.ndarray], shape: list[int]) -> None:
    """Store camera `key`'s frames as PNG images in the rows (an ``image`` feature), no video."""
    for e in range(SIZE["episodes"]):
        frames = robot_frames(ROWS, SIZE["height"], SIZE["width"], seed=e)
        path = root / V21_DATA.format(e)
        images = pa.array([{"bytes": _png(convert(f)), "path": None} for f in frames])
        pq.write_table(pq.read_table(path).append_column(key, images), path)
    _info(root, lambda info: info["features"].__setitem__(key, {"dtype": "image", "shape": shape,
                                                                "names": ["height", "width", "channels"]}))


# --- the datasets whose meaning is clear -------------------------------------------------------------


def template_of_v3(root):  # the bimanual dataset of the issue: v2.1 paths named with v3.0's placeholders
    _info(root, lambda info: info.update(data_path="data/chunk-{chunk_index:03d}/episode_{episode_index:06d}.parquet",
                                         video_path="videos/chunk-{chunk_index:03d}/{video_key}/episode_{file_index:06d}.mp4"))


def template_without_placeholders(root):
    _info(root, lambda info: info.update(data_path="data/train.parquet"))


def templates_missing(root):
    _info(root, lambda info: [info.pop(k) for k in ("data_path", "video_path", "chunks_size")])


def files_elsewhere(root):
    (root / "data/chunk-000").rename(root / "data/train")


def wall_clock_timestamps(root):
    _tables(root, lambda t: _set_column(t, "timestamp", pa.array(1.7e9 + np.arange(t.num_rows) * 0.1037)))


def video_longer(root):
    _videos(root, lambda f: np.concatenate([f, f[-1:]]), episodes=[0])


def video_short(root):
    _videos(root, lambda f: f[:-1], episodes=[1])


def first_frame_repeated(root):
    _videos(root, lambda f: np.concatenate([f[:1], f]), episodes=[0, 2])


def static_video(root):
    _videos(root, lambda f: np.repeat(f[:1], len(f), axis=0))


def bookkeeping_columns_missing(root):
    _tables(root, lambda t: t.drop_columns(["index", "task_index", "frame_index", "timestamp"]))


def extra_columns(root):
    _tables(root, lambda t: t.append_column("observation.effort", pa.array(np.ones(t.num_rows))))


def nested_actions(root):
    _tables(root, lambda t: _set_column(t, "action", pa.array([[row] for row in t.column("action").to_pylist()])))


def scalar_action(root):
    _info(root, lambda info: info["features"]["action"].update(shape=[1]))
    _tables(root, lambda t: _set_column(t, "action", pa.array([row[0] for row in t.column("action").to_pylist()])))


def no_state(root):
    _info(root, lambda info: info["features"].pop("observation.state"))
    _tables(root, lambda t: t.drop_columns(["observation.state"]))


def state_named_otherwise(root):
    _info(root, lambda info: info["features"].__setitem__("observation.joints", info["features"].pop("observation.state")))
    _tables(root, lambda t: t.rename_columns(["observation.joints" if n == "observation.state" else n for n in t.column_names]))


def meta_files_missing(root):
    (root / "meta/tasks.jsonl").unlink()


def cut_to_first_episodes(root):
    _episodes(root, lambda row: row)
    extra = [{"episode_index": e, "tasks": ["pick up the red cube"], "length": ROWS} for e in range(4, 50)]
    with (root / "meta/episodes.jsonl").open("a") as file:
        file.writelines(json.dumps(row) + "\n" for row in extra)
    _info(root, lambda info: info.update(total_episodes=50))


def shape_under_info(root):
    _info(root, lambda info: info["features"]["observation.images.front"].pop("shape"))


def shape_under_video_info(root):
    def change(info):
        camera = info["features"]["observation.images.front"]
        camera.pop("shape")
        camera["video_info"] = camera.pop("info")
    _info(root, change)


def images_in_rows(root):
    _images_in_rows(root, "observation.images.top", lambda f: f, [SIZE["height"], SIZE["width"], 3])
    _info(root, lambda info: info["features"].pop("observation.images.front"))


def grayscale_images(root):
    _images_in_rows(root, "observation.images.top", lambda f: f.mean(-1).astype(np.uint8), [SIZE["height"], SIZE["width"], 1])
    _info(root, lambda info: info["features"].pop("observation.images.front"))


def depth_images(root):
    _images_in_rows(root, "observation.images.depth", lambda f: (f[..., 0].astype(np.uint16) * 200),
                    [SIZE["height"], SIZE["width"], 1])
    _info(root, lambda info: info["features"].pop("observation.images.front"))


def grayscale_video(root):  # one channel declared, grey frames in a colour stream (as x264 stores grey)
    _videos(root, lambda f: np.repeat(f.mean(-1, keepdims=True).astype(np.uint8), 3, axis=-1))
    _info(root, lambda info: info["features"]["observation.images.front"].update(shape=[SIZE["height"], SIZE["width"], 1]))


def cameras_of_different_sizes(root):
    for e in range(SIZE["episodes"]):
        encode_video(root / V21_VIDEO.format(e).replace("front", "wrist"), robot_frames(ROWS, 16, 16, seed=e), 10)
    _info(root, lambda info: info["features"].__setitem__("observation.images.wrist", {
        "dtype": "video", "shape": [16, 16, 3], "names": ["height", "width", "channels"]}))


def _codec(codec):
    return lambda root: _videos(root, lambda f: f, codec=codec)


def av1(root):
    # SVT-AV1 prints its settings to stderr (Svt[info] lines) at every encoder start unless SVT_LOG
    # says otherwise; 1 keeps its errors. It has no encoder option for this.
    with mock.patch.dict(os.environ, {"SVT_LOG": "1"}):
        _videos(root, lambda f: f, codec=VideoCodec("libsvtav1", "yuv420p", {}))


def codec_mislabelled(root):  # info.json says h264 (robot_datasets' default), the file is mpeg4
    _videos(root, lambda f: f, codec=VideoCodec("mpeg4", "yuv420p", {"qscale": "2"}))


def several_tasks_per_episode(root):
    _episodes(root, lambda row: row | {"tasks": [row["tasks"][0], "then wave"]})


def tasks_only_by_index(root):
    _episodes(root, lambda row: {k: v for k, v in row.items() if k != "tasks"})


def one_task_only_in_tasks_jsonl(root):
    _episodes(root, lambda row: {k: v for k, v in row.items() if k != "tasks"})
    (root / "meta/tasks.jsonl").write_text(json.dumps({"task_index": 0, "task": "pick up the red cube"}) + "\n")
    _tables(root, lambda t: t.drop_columns(["task_index"]))


def no_episode_list(root):
    (root / "meta/episodes.jsonl").unlink()


def v3_without_index(root):
    _tables(root, lambda t: t.drop_columns(["index"]))


def v3_cut(root):
    _info(root, lambda info: info.update(total_episodes=40))


def published_bimanual(root):
    """The issue's dataset: two cameras of a bimanual arm, v2.1 with v3.0's placeholders, and many small
    departures at once (wall-clock timestamps, bookkeeping columns missing, a video a frame short, one
    starting with a repeat, shape only under 'info', joint units in the thousands, several tasks)."""
    template_of_v3(root)
    wall_clock_timestamps(root)
    _tables(root, lambda t: t.drop_columns(["index", "task_index"]))
    video_short(root)
    first_frame_repeated(root)
    shape_under_info(root)
    several_tasks_per_episode(root)


# --- the datasets whose meaning is not clear: refused with one line naming the file, field and fix ---


def no_task_anywhere(root):
    _episodes(root, lambda row: {k: v for k, v in row.items() if k != "tasks"})
    (root / "meta/tasks.jsonl").unlink()


def video_half_missing(root):
    _videos(root, lambda f: f[: len(f) // 2], episodes=[0])


def unknown_placeholder(root):
    _info(root, lambda info: info.update(data_path="data/{split}/episode_{episode_index:06d}.parquet"))


def no_action(root):
    _info(root, lambda info: info["features"].pop("action"))


def no_fps(root):
    _info(root, lambda info: info.pop("fps"))


def no_files(root):
    for path in (root / "data").rglob("*.parquet"):
        path.unlink()


Builder = Callable[[Path], None]
CORPUS: dict[str, tuple[Builder, dict, str | None]] = {
    # name: (builder, write_robot_dataset options besides SIZE, None = read, or a piece of the error)
    "template_of_v3": (template_of_v3, dict(cameras=("left", "right")), None),
    "template_without_placeholders": (template_without_placeholders, {}, None),
    "templates_missing": (templates_missing, {}, None),
    "files_elsewhere": (files_elsewhere, {}, None),
    "wall_clock_timestamps": (wall_clock_timestamps, {}, None),
    "video_longer": (video_longer, {}, None),
    "video_short": (video_short, {}, None),
    "first_frame_repeated": (first_frame_repeated, {}, None),
    "static_video": (static_video, {}, None),
    "bookkeeping_columns_missing": (bookkeeping_columns_missing, {}, None),
    "extra_columns": (extra_columns, {}, None),
    "nested_actions": (nested_actions, {}, None),
    "scalar_action": (scalar_action, {}, None),
    "no_state": (no_state, {}, None),
    "state_named_otherwise": (state_named_otherwise, {}, None),
    "meta_files_missing": (meta_files_missing, {}, None),
    "cut_to_first_episodes": (cut_to_first_episodes, {}, None),
    "shape_under_info": (shape_under_info, {}, None),
    "shape_under_video_info": (shape_under_video_info, dict(version="v2.0"), None),
    "images_in_rows": (images_in_rows, dict(without_video=("front",)), None),
    "grayscale_images": (grayscale_images, dict(without_video=("front",)), None),
    "depth_images": (depth_images, dict(without_video=("front",)), None),
    "grayscale_video": (grayscale_video, {}, None),
    "cameras_of_different_sizes": (cameras_of_different_sizes, {}, None),
    "mpeg4": (_codec(VideoCodec("mpeg4", "yuv420p", {"qscale": "2"})), {}, None),
    "hevc": (_codec(VideoCodec("libx265", "yuv420p", {"x265-params": "log-level=none"})), {}, None),
    "av1": (av1, {}, None),
    "vp9": (_codec(VideoCodec("libvpx-vp9", "yuv420p", {})), {}, None),
    "codec_mislabelled": (codec_mislabelled, {}, None),
    "raw_joint_units": (lambda root: None, dict(action_scale=4000.0), None),
    "several_tasks_per_episode": (several_tasks_per_episode, {}, None),
    "tasks_only_by_index": (tasks_only_by_index, {}, None),
    "one_task_only_in_tasks_jsonl": (one_task_only_in_tasks_jsonl, {}, None),
    "no_episode_list": (no_episode_list, {}, None),
    "v3_without_index": (v3_without_index, dict(version="v3.0"), None),
    "v3_cut": (v3_cut, dict(version="v3.0"), None),
    "published_bimanual": (published_bimanual, dict(cameras=("front", "right"), action_scale=4000.0), None),
    "no_task_anywhere": (no_task_anywhere, {}, "has no task"),
    "video_half_missing": (video_half_missing, {}, "frames for 13 data rows"),
    "unknown_placeholder": (unknown_placeholder, {}, "names placeholders ['split']"),
    "no_action": (no_action, {}, "no 'action' feature"),
    "no_fps": (no_fps, {}, "field 'fps' is None"),
    "no_files": (no_files, {}, "parquet file not found"),
}


def build(root: Path, name: str) -> Path:
    """Write corpus dataset `name` into `root` and return it."""
    builder, options, _ = CORPUS[name]
    write_robot_dataset(root, **(SIZE | options))
    builder(root)
    return root
