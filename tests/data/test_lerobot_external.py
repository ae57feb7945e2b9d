"""Datasets not written by gymnast: LeRobot v2.1 (built here by hand) and v3.0 without gymnast columns."""

from __future__ import annotations

import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from data_helpers import make_episode, smooth_frames
from PIL import Image

from gymnast.data.lerobot import DatasetError, EpisodeDataset, LeRobotWriter
from gymnast.data.lerobot_format import EpisodeRef
from gymnast.data.lerobot_frames import match_frames_to_rows
from gymnast.data.schema import EpisodeInfo
from gymnast.utils.video import encode_video, psnr

FPS = 10
TASK = "pick up the cube"


def write_v21(root, lengths=(5, 8), with_next=True, channels_first=False):
    """A small v2.1 dataset as LeRobot 0.2 wrote it: one parquet and one mp4 per episode."""
    rng = np.random.default_rng(0)
    shape, names = (
        ([3, 32, 32], ["channels", "height", "width"])
        if channels_first
        else ([32, 32, 3], ["height", "width", "channel"])
    )
    features = {
        "observation.images.top": {
            "dtype": "video",
            "shape": shape,
            "names": names,
            "info": {"video.fps": FPS},
        },
        "observation.state": {"dtype": "float32", "shape": [6], "names": None},
        "action": {"dtype": "float32", "shape": [6], "names": None},
        **{
            k: {"dtype": "int64", "shape": [1], "names": None}
            for k in ("frame_index", "episode_index", "index", "task_index")
        },
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    }
    if with_next:
        features["next.reward"] = {"dtype": "float32", "shape": [1], "names": None}
        features["next.success"] = {"dtype": "bool", "shape": [1], "names": None}
    info = {
        "codebase_version": "v2.1",
        "robot_type": "koch",
        "total_episodes": len(lengths),
        "total_frames": sum(lengths),
        "total_tasks": 1,
        "total_videos": len(lengths),
        "total_chunks": 1,
        "chunks_size": 1000,
        "fps": FPS,
        "splits": {"train": f"0:{len(lengths)}"},
        "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        "video_path": "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4",
        "features": features,
    }
    (root / "meta").mkdir(parents=True)
    (root / "meta/info.json").write_text(json.dumps(info))
    (root / "meta/tasks.jsonl").write_text(json.dumps({"task_index": 0, "task": TASK}) + "\n")
    episodes, first = [], 0
    for e, length in enumerate(lengths):
        columns = {
            "observation.state": rng.normal(size=(length, 6)).astype(np.float32),
            "action": rng.normal(size=(length, 6)).astype(np.float32),
            "timestamp": np.arange(length, dtype=np.float32) / FPS,
            "frame_index": np.arange(length),
            "episode_index": np.full(length, e),
            "index": first + np.arange(length),
            "task_index": np.zeros(length, np.int64),
        }
        if with_next:
            columns["next.reward"] = rng.normal(size=length).astype(np.float32)
            columns["next.success"] = np.arange(length) == (length - 1 if e == 0 else length + 1)
        table = pa.table({k: pa.array(list(v)) if v.ndim == 2 else pa.array(v) for k, v in columns.items()})
        (root / "data/chunk-000").mkdir(parents=True, exist_ok=True)
        pq.write_table(table, root / f"data/chunk-000/episode_{e:06d}.parquet")
        frames = smooth_frames(length, 32, seed=e)
        encode_video(root / f"videos/chunk-000/observation.images.top/episode_{e:06d}.mp4", frames, FPS)
        episodes.append((columns, frames))
        first += length
    lines = [json.dumps({"episode_index": e, "tasks": [TASK], "length": n}) for e, n in enumerate(lengths)]
    (root / "meta/episodes.jsonl").write_text("\n".join(lines) + "\n")
    return episodes


def test_v21_dataset_reads_with_defaults_for_missing_facts(tmp_path):
    written = write_v21(tmp_path)
    dataset = EpisodeDataset(tmp_path)
    assert (len(dataset), dataset.version, dataset.fps, dataset.camera_key) == (2, "v2.1", FPS, "top")
    assert dataset.image_shape == (32, 32, 3) and dataset.lengths == [4, 7]
    assert dataset.episodes == [
        EpisodeInfo(TASK, TASK, True, "expert", 0.0, 0, "external"),  # next.success set on its last row
        EpisodeInfo(TASK, TASK, False, "expert", 0.0, 1, "external"),  # the seed: each episode its own scene
    ]
    for i, (columns, frames) in enumerate(written):
        episode = dataset.load(i)
        steps = len(frames) - 1  # the last action leads to a frame that was not recorded
        np.testing.assert_array_equal(episode.actions, columns["action"][:steps])
        np.testing.assert_array_equal(episode.states, columns["observation.state"])
        np.testing.assert_array_equal(episode.rewards, columns["next.reward"][:steps])
        np.testing.assert_array_equal(episode.successes, columns["next.success"][:steps])
        assert episode.env_states.shape == (steps + 1, 0)
        assert psnr(frames, episode.frames).per_frame.min() >= 40.0


def test_v21_dataset_without_rewards_or_success_flags(tmp_path):
    write_v21(tmp_path, lengths=(6,), with_next=False, channels_first=True)
    dataset = EpisodeDataset(tmp_path)
    assert dataset.image_shape == (32, 32, 3)
    episode = dataset.load(0)
    assert episode.info.success and episode.successes.tolist() == [False] * 4 + [True]
    np.testing.assert_array_equal(episode.rewards, np.zeros(5, np.float32))


def test_v21_missing_data_file_names_it(tmp_path):
    write_v21(tmp_path)
    missing = tmp_path / "data/chunk-000/episode_000000.parquet"  # the first: not a dataset cut to its first episodes
    missing.unlink()
    with pytest.raises(FileNotFoundError, match=re.escape(str(missing))):
        EpisodeDataset(tmp_path).load(0)


def test_v21_dataset_cut_to_its_first_episodes_reads_those_with_a_deviation(tmp_path):
    write_v21(tmp_path)
    (tmp_path / "data/chunk-000/episode_000001.parquet").unlink()
    dataset = EpisodeDataset(tmp_path)
    assert len(dataset) == 1 and dataset.load(0).length == 4
    assert any("data files exist for the first 1" in str(d) for d in dataset.deviations)


def test_v3_dataset_without_gymnast_columns_gets_the_defaults(tmp_path):
    episode = make_episode(6, seed=0)
    with LeRobotWriter(tmp_path) as writer:
        writer.add(episode)
    meta = tmp_path / "meta/episodes/chunk-000/file-000.parquet"
    table = pq.read_table(meta)
    pq.write_table(table.drop_columns([n for n in table.column_names if n.startswith("gymnast/")]), meta)
    data = tmp_path / "data/chunk-000/file-000.parquet"
    pq.write_table(pq.read_table(data).drop_columns(["action_is_pad"]), data)

    dataset = EpisodeDataset(tmp_path)
    expected = EpisodeInfo(
        "open the drawer",
        "open the drawer",
        bool(episode.successes.any()),
        "expert",
        0.0,
        0,
        "external",
    )
    assert dataset.episodes == [expected]
    loaded = dataset.load(0)
    np.testing.assert_array_equal(loaded.actions, episode.actions)  # the padded last row is dropped
    np.testing.assert_array_equal(loaded.rewards, episode.rewards)


def test_images_stored_in_the_rows_are_read_when_there_is_no_video(tmp_path):
    written = write_v21(tmp_path, lengths=(4,))
    info = json.loads((tmp_path / "meta/info.json").read_text())
    info["features"]["observation.images.top"]["dtype"] = "image"
    (tmp_path / "meta/info.json").write_text(json.dumps(info))
    frames = written[0][1]
    pngs = []
    for frame in frames:
        buffer = io.BytesIO()
        Image.fromarray(frame).save(buffer, format="PNG")
        pngs.append({"bytes": buffer.getvalue(), "path": None})
    path = tmp_path / "data/chunk-000/episode_000000.parquet"
    pq.write_table(pq.read_table(path).append_column("observation.images.top", pa.array(pngs)), path)
    shutil.rmtree(tmp_path / "videos")

    np.testing.assert_array_equal(EpisodeDataset(tmp_path).load(0).frames, frames)  # PNG is lossless
    np.testing.assert_array_equal(EpisodeDataset(tmp_path).first_frame(0), frames[0])  # from the first row alone
    np.testing.assert_array_equal(EpisodeDataset(tmp_path).frames(0, 1, 3), frames[1:3])  # from those rows alone



def test_a_video_one_frame_short_of_its_rows_reuses_its_last_frame_with_a_warning(tmp_path, caplog):
    columns, frames = write_v21(tmp_path, lengths=(6,))[0]
    video = tmp_path / "videos/chunk-000/observation.images.top/episode_000000.mp4"
    encode_video(video, frames[:-1], FPS)
    with caplog.at_level("WARNING"):
        episode = EpisodeDataset(tmp_path).load(0)
    assert "has 5 frames for 6 data rows" in caplog.text and str(video) in caplog.text
    assert episode.frames.shape == (6, 32, 32, 3)  # one frame per row, the last row's its neighbour's
    assert psnr(frames[:5], episode.frames[:5]).per_frame.min() >= 40.0
    np.testing.assert_array_equal(episode.frames[5], episode.frames[4])
    np.testing.assert_array_equal(episode.actions, columns["action"][:5])
    dataset = EpisodeDataset(tmp_path)
    np.testing.assert_array_equal(dataset.frames(0, 5, 6), episode.frames[5:])  # the missing last frame alone
    np.testing.assert_array_equal(dataset.frames(0, 3, 6), episode.frames[3:])


def test_a_video_one_frame_longer_than_its_rows_reads_the_rows_frames():
    frames = smooth_frames(7, 32, seed=0)
    ref = EpisodeRef(0, 6, TASK, Path("data.parquet"), None, Path("v.mp4"), (0.0, 0.6), {}, Path("meta.jsonl"))
    np.testing.assert_array_equal(match_frames_to_rows(frames, 6, ref), frames[:6])


def test_a_video_two_frames_short_is_an_error_naming_the_file(tmp_path):
    written = write_v21(tmp_path, lengths=(6,))
    video = tmp_path / "videos/chunk-000/observation.images.top/episode_000000.mp4"
    encode_video(video, written[0][1][:-2], FPS)
    with pytest.raises(DatasetError, match=re.escape(f"{video}: camera 'observation.images.top' of episode 0 has 4 frames for 6 data rows")):
        EpisodeDataset(tmp_path).load(0)
