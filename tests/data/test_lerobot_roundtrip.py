"""LeRobot v3.0 writer + reader: round trips, the layout LeRobot expects, several files, stats."""

from __future__ import annotations

import json
import os

import numpy as np
import pyarrow.parquet as pq
import pytest
from data_helpers import assert_same_numbers, make_episode, three_episodes

from gymnast.data.lerobot import EpisodeDataset, LeRobotWriter
from gymnast.data.lerobot_format import INFO_COLUMNS
from gymnast.utils.video import psnr


def test_round_trip_keeps_numbers_exact_and_frames_within_the_recorded_codec_error(tmp_path):
    episodes = three_episodes()
    writer = LeRobotWriter(tmp_path)
    for episode in episodes:
        writer.add(episode)
    assert writer.flush() == 3

    dataset = EpisodeDataset(tmp_path)
    assert (len(dataset), dataset.fps, dataset.camera_key, dataset.image_shape) == (
        3,
        80,
        "front",
        (48, 48, 3),
    )
    assert dataset.lengths == [12, 20, 7]
    assert dataset.episodes == [e.info for e in episodes]
    recorded = pq.read_table(tmp_path / "meta/episodes/chunk-000/file-000.parquet").column(
        "gymnast/video_psnr_db"
    )
    for i, (episode, db) in enumerate(zip(episodes, recorded.to_pylist(), strict=True)):
        loaded = dataset.load(i)
        assert_same_numbers(loaded, episode)
        assert db >= 40.0
        assert psnr(episode.frames, loaded.frames).per_frame.min() == pytest.approx(db)
    assert dataset.info["gymnast"]["video_psnr_db"]["min"] == pytest.approx(min(recorded.to_pylist()))


def test_layout_and_metadata_follow_lerobot_v3(tmp_path):
    episodes = three_episodes()
    with LeRobotWriter(tmp_path) as writer:  # flushes on exit
        for episode in episodes:
            writer.add(episode)

    info = json.loads((tmp_path / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["robot_type"] == "sawyer" and info["fps"] == 80
    assert (info["total_episodes"], info["total_frames"], info["total_tasks"]) == (3, 13 + 21 + 8, 2)
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    assert info["splits"] == {"train": "0:3"}
    video = info["features"]["observation.images.front"]
    assert video["dtype"] == "video" and video["shape"] == [48, 48, 3]
    assert video["info"]["video.codec"] == "h264" and video["info"]["video.fps"] == 80
    assert info["features"]["action"]["shape"] == [4] and info["features"]["observation.environment_state"][
        "shape"
    ] == [39]

    assert pq.read_table(tmp_path / "meta/tasks.parquet").to_pydict() == {
        "task_index": [0, 1],
        "task": ["open the drawer", "pull the drawer open"],
    }
    meta = pq.read_table(tmp_path / "meta/episodes/chunk-000/file-000.parquet").to_pydict()
    assert meta["episode_index"] == [0, 1, 2] and meta["length"] == [13, 21, 8]
    assert meta["dataset_from_index"] == [0, 13, 34] and meta["dataset_to_index"] == [13, 34, 42]
    assert meta["tasks"] == [["open the drawer"], ["pull the drawer open"], ["open the drawer"]]
    assert meta["videos/observation.images.front/from_timestamp"] == [0.0, 13 / 80, 34 / 80]
    assert meta["videos/observation.images.front/to_timestamp"] == [13 / 80, 34 / 80, 42 / 80]
    assert meta["gymnast/behaviour"] == ["expert"] * 3 and set(INFO_COLUMNS) <= set(meta)
    assert np.asarray(meta["stats/observation.images.front/mean"][0]).shape == (3, 1, 1)

    data = pq.read_table(tmp_path / "data/chunk-000/file-000.parquet").to_pydict()
    assert data["index"] == list(range(42)) and data["frame_index"][:14] == [*range(13), 0]
    assert data["action_is_pad"][:13] == [False] * 12 + [True] and data["action"][12] == [0.0] * 4
    assert data["task_index"][13] == 1 and data["timestamp"][1] == pytest.approx(1 / 80)
    assert data["next.done"][10:13] == [False, True, True]


def test_stats_match_the_data(tmp_path):
    episodes = three_episodes()
    writer = LeRobotWriter(tmp_path)
    for episode in episodes:
        writer.add(episode)
        writer.flush()  # stats are aggregated across flushes
    stats = json.loads((tmp_path / "meta/stats.json").read_text())
    actions = np.concatenate([e.actions for e in episodes])  # padding rows are left out
    np.testing.assert_allclose(stats["action"]["mean"], actions.mean(0), rtol=1e-5)
    np.testing.assert_allclose(stats["action"]["std"], actions.std(0), rtol=1e-5)
    np.testing.assert_allclose(stats["action"]["min"], actions.min(0))
    assert stats["action"]["count"] == [39] and stats["observation.state"]["count"] == [42]
    frames = np.concatenate([e.frames for e in episodes]).reshape(-1, 3) / 255.0
    np.testing.assert_allclose(np.ravel(stats["observation.images.front"]["mean"]), frames.mean(0), rtol=1e-6)
    np.testing.assert_allclose(np.ravel(stats["observation.images.front"]["std"]), frames.std(0), rtol=1e-6)
    assert np.asarray(stats["observation.images.front"]["max"]).shape == (3, 1, 1)


def test_each_flush_writes_new_files_and_chunks_roll_over(tmp_path):
    episodes = [make_episode(5 + i, seed=i) for i in range(5)]
    writer = LeRobotWriter(tmp_path, chunks_size=2)
    for group in (episodes[:2], episodes[2:3], episodes[3:]):
        for episode in group:
            writer.add(episode)
        writer.flush()
    assert writer.flush() == 0  # nothing staged: no new file
    files = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("file-*"))
    assert files == [
        "data/chunk-000/file-000.parquet",
        "data/chunk-000/file-001.parquet",
        "data/chunk-001/file-000.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "meta/episodes/chunk-000/file-001.parquet",
        "meta/episodes/chunk-001/file-000.parquet",
        "videos/observation.images.front/chunk-000/file-000.mp4",
        "videos/observation.images.front/chunk-000/file-001.mp4",
        "videos/observation.images.front/chunk-001/file-000.mp4",
    ]
    dataset = EpisodeDataset(tmp_path)
    assert len(dataset) == 5
    for i, episode in enumerate(episodes):
        assert_same_numbers(dataset.load(i), episode)


def test_appending_after_reopening_continues_the_indices(tmp_path):
    first, second = make_episode(6, seed=0), make_episode(9, seed=1)
    with LeRobotWriter(tmp_path) as writer:
        writer.add(first)
    with LeRobotWriter(tmp_path) as writer:
        assert writer.num_episodes == 1
        writer.add(second)
    dataset = EpisodeDataset(tmp_path)
    assert [dataset.load(i).info for i in range(2)] == [first.info, second.info]
    data = pq.read_table(tmp_path / "data/chunk-000/file-001.parquet").to_pydict()
    assert data["episode_index"][0] == 1 and data["index"][0] == 7


def test_keys_list_committed_and_staged_episodes_and_duplicates_are_refused(tmp_path):
    a, b = make_episode(4, seed=0), make_episode(4, seed=1)
    writer = LeRobotWriter(tmp_path)
    writer.add(a)
    writer.flush()
    writer.add(b)
    assert writer.keys() == {a.info.key, b.info.key}
    assert (writer.num_episodes, writer.num_staged) == (1, 1)
    with pytest.raises(ValueError, match="already in"):
        writer.add(make_episode(4, seed=0))


def test_dataset_without_environment_state_round_trips(tmp_path):
    episode = make_episode(5, env_dim=0)
    with LeRobotWriter(tmp_path) as writer:
        writer.add(episode)
    dataset = EpisodeDataset(tmp_path)
    assert "observation.environment_state" not in dataset.info["features"]
    assert_same_numbers(dataset.load(0), episode)


@pytest.mark.slow
def test_real_metaworld_frames_are_recorded_above_40db(tmp_path):
    os.environ.setdefault("MUJOCO_GL", "egl")
    mujoco = pytest.importorskip("mujoco")
    metaworld = pytest.importorskip("metaworld")
    env = metaworld.env_dict.ALL_V3_ENVIRONMENTS["drawer-open-v3"]()
    env._partially_observable, env._freeze_rand_vec, env._set_task_called = False, False, True
    env.reset()
    try:
        renderer = mujoco.Renderer(env.model, 64, 64)
    except Exception as e:  # no OpenGL here: nothing to measure
        pytest.skip(f"cannot render: {e}")
    camera = mujoco.MjvCamera()
    camera.type, camera.distance, camera.azimuth, camera.elevation = (
        mujoco.mjtCamera.mjCAMERA_FREE,
        1.4,
        135,
        -30,
    )
    camera.lookat[:] = [0, 0.65, 0.1]
    rng, frames = np.random.default_rng(0), []
    for _ in range(20):
        env.step(rng.uniform(-1, 1, 4))
        renderer.update_scene(env.data, camera=camera)
        frames.append(renderer.render().copy())
    renderer.close()
    with LeRobotWriter(tmp_path) as writer:
        writer.add(make_episode(19, frames=np.stack(frames)))
    assert EpisodeDataset(tmp_path).info["gymnast"]["video_psnr_db"]["min"] >= 40.0
