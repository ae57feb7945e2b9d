"""Datasets with several cameras: recorded by collect, resumed, read back, refused when views disagree."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from data_helpers import make_episode, smooth_frames
from robot_datasets import write_robot_dataset

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.data import lerobot_writer
from gymnast.data.collect import CollectConfig, collect, plan_episodes, record_episode
from gymnast.data.lerobot import DatasetError, EpisodeDataset, LeRobotWriter
from gymnast.utils.video import psnr

TWO = EnvConfig(image_size=32, horizon=20, cameras=("front", "gripper"))
ONE = dataclasses.replace(TWO, cameras=("front",))
GRIPPER_VIDEO = "videos/observation.images.gripper/chunk-000/file-000.mp4"
META = "meta/episodes/chunk-000/file-000.parquet"


def recipe(env: EnvConfig, episodes: int = 2) -> CollectConfig:
    return CollectConfig(tasks="reach-v3", episodes_per_task=episodes, failure_fraction=0, workers=1, env=env)


@pytest.fixture(scope="module")
def two_cameras(tmp_path_factory) -> Path:
    """Two short reach-v3 episodes recorded from the front and the gripper cameras."""
    out = tmp_path_factory.mktemp("two_cameras")
    collect(recipe(TWO), out, progress=False)
    return out


def with_views(episode, **views):
    """The episode with camera views: front (its frames) first, then the given ones."""
    return dataclasses.replace(episode, views={"front": episode.frames, **views})


def two_camera_writer_dataset(root: Path, size: int = 48) -> Path:
    with LeRobotWriter(root, cameras=("front", "gripper")) as writer:
        for seed, steps in enumerate((6, 8)):
            episode = make_episode(steps, seed=seed, size=size)
            writer.add(with_views(episode, gripper=smooth_frames(steps + 1, size, seed=seed + 10)))
    return root


def test_a_two_camera_collect_round_trips_every_view_within_the_codec_error(two_cameras):
    dataset = EpisodeDataset(two_cameras, cameras=("front", "gripper"))
    info, stats = dataset.info, json.loads((two_cameras / "meta/stats.json").read_text())
    for key in ("observation.images.front", "observation.images.gripper"):
        assert info["features"][key]["dtype"] == "video" and info["features"][key]["shape"] == [32, 32, 3]
        assert info["features"][key]["info"]["video.codec"] == "h264"
        assert np.asarray(stats[key]["mean"]).shape == (3, 1, 1)
        assert f"videos/{key}/from_timestamp" in pq.read_schema(two_cameras / META).names
    codec_floor = info["gymnast"]["video_psnr_db"]["min"]
    jobs = {job.key: job for job in plan_episodes(recipe(TWO))}
    for i, facts in enumerate(dataset.episodes):
        loaded, fresh = dataset.load(i), record_episode(jobs[facts.key])
        assert list(loaded.views) == ["front", "gripper"] and loaded.views["front"] is loaded.frames
        np.testing.assert_array_equal(loaded.actions, fresh.actions)
        for name in ("front", "gripper"):
            assert psnr(fresh.views[name], loaded.views[name]).per_frame.min() >= codec_floor - 1e-6
        assert not np.array_equal(loaded.views["front"], loaded.views["gripper"])


def test_the_primary_view_is_exactly_what_a_one_camera_collect_records(two_cameras, tmp_path):
    collect(recipe(ONE), tmp_path, progress=False)
    one, two = EpisodeDataset(tmp_path), EpisodeDataset(two_cameras)
    assert one.episodes == two.episodes
    for i in range(len(one)):
        np.testing.assert_array_equal(one.load(i).frames, two.load(i).frames)
    for job in plan_episodes(recipe(ONE)):  # the raw renders too, before any codec
        alone = record_episode(job)
        beside = record_episode(dataclasses.replace(job, env=TWO))
        np.testing.assert_array_equal(alone.frames, beside.frames)


def test_a_two_camera_collection_resumes_and_refuses_other_cameras(tmp_path):
    collect(recipe(TWO, episodes=1), tmp_path, progress=False)
    collect(recipe(TWO, episodes=2), tmp_path, progress=False)  # extends it
    dataset = EpisodeDataset(tmp_path, cameras=("front", "gripper"))
    assert len(dataset) == 2 and all(dataset.load(i).views["gripper"].shape == (21, 32, 32, 3) for i in range(2))
    with pytest.raises(ValueError, match="records cameras front,gripper, not front; rerun with --cameras front,gripper"):
        collect(recipe(ONE, episodes=2), tmp_path, progress=False)


def test_staged_views_survive_until_a_later_writer_flushes_them(tmp_path):
    episode = make_episode(5, seed=0)
    gripper = smooth_frames(6, 48, seed=7)
    LeRobotWriter(tmp_path, cameras=("front", "gripper")).add(with_views(episode, gripper=gripper))  # no flush
    assert LeRobotWriter(tmp_path, cameras=("front", "gripper")).flush() == 1
    loaded = EpisodeDataset(tmp_path, cameras=("front", "gripper")).load(0)
    assert psnr(gripper, loaded.views["gripper"]).per_frame.min() >= 40.0


def test_a_flush_interrupted_before_its_commit_leaves_no_view_behind_and_is_redone(tmp_path, monkeypatch):
    cameras = ("front", "gripper")
    writer = LeRobotWriter(tmp_path, cameras=cameras)
    writer.add(with_views(make_episode(5, seed=0), gripper=smooth_frames(6, 48, seed=9)))
    writer.flush()
    second = with_views(make_episode(6, seed=1), gripper=smooth_frames(7, 48, seed=8))
    writer.add(second)

    def die_at_commit(path, obj):
        if str(path).endswith("info.json"):
            raise OSError("killed")
        real_write_json(path, obj)

    real_write_json = lerobot_writer.write_json
    monkeypatch.setattr(lerobot_writer, "write_json", die_at_commit)
    with pytest.raises(OSError, match="killed"):
        writer.flush()
    monkeypatch.setattr(lerobot_writer, "write_json", real_write_json)
    orphan = tmp_path / GRIPPER_VIDEO.replace("file-000", "file-001")
    assert orphan.exists()
    resumed = LeRobotWriter(tmp_path, cameras=cameras)  # a new process: recovers the last commit
    assert not orphan.exists() and (resumed.num_episodes, resumed.num_staged) == (1, 1)
    resumed.flush()
    loaded = EpisodeDataset(tmp_path, cameras=cameras).load(1)
    assert psnr(second.views["gripper"], loaded.views["gripper"]).per_frame.min() >= 40.0


def test_the_writer_refuses_an_episode_without_its_cameras_and_names_them(tmp_path):
    writer = LeRobotWriter(tmp_path, cameras=("front", "gripper"))
    with pytest.raises(ValueError, match=r"has cameras \['front'\] but .* records \['front', 'gripper'\]"):
        writer.add(make_episode(4, seed=0))


def assert_start_of(dataset: EpisodeDataset, i: int) -> None:
    """`first_frame`, `frames` and `columns` of episode i are what `load` gives, to the bit."""
    episode, columns = dataset.load(i), dataset.columns(i)
    np.testing.assert_array_equal(dataset.first_frame(i), episode.observed_frames[0])
    last = len(episode.observed_frames)
    for first, stop in ((0, last), (1, 3), (last // 2, last), (last - 1, last)):  # the end: a short video's
        np.testing.assert_array_equal(dataset.frames(i, first, stop), episode.observed_frames[first:stop])
    for field in ("states", "env_states", "actions", "rewards", "successes", "full_states"):
        np.testing.assert_array_equal(getattr(columns, field), getattr(episode, field))
    assert columns.info == episode.info


@pytest.mark.parametrize("fit", [None, "resize", "crop"])
def test_a_first_frame_and_the_columns_are_the_loaded_episodes_without_decoding_it(tmp_path, fit):
    root = two_camera_writer_dataset(tmp_path)
    for cameras in (("front", "gripper"), ("gripper", "front"), ("front",)):
        dataset = EpisodeDataset(root, cameras=cameras)
        dataset = dataset.fitted(32, fit) if fit else dataset
        for i in range(len(dataset)):  # the second episode starts inside the video file: a seek
            assert_start_of(dataset, i)
        assert dataset.first_frame(1).shape == (dataset.image_shape[0], len(cameras) * dataset.image_shape[1], 3)


def test_a_range_of_frames_outside_the_episode_is_refused_naming_it(tmp_path):
    dataset = EpisodeDataset(two_camera_writer_dataset(tmp_path), cameras=("front", "gripper"))
    frames = len(dataset.load(0).frames)
    for first, stop in ((0, frames + 1), (-1, 2), (3, 3)):
        with pytest.raises(IndexError, match=rf"frames \[{first}, {stop}\) are outside episode 0 .* {frames} frames"):
            dataset.frames(0, first, stop)


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_another_robots_first_frames_are_its_loaded_ones(tmp_path, version):
    root = write_robot_dataset(tmp_path, version=version, episodes=3, steps=5, height=24, width=32,
                               cameras=("front", "wrist"), short_video=True)
    dataset = EpisodeDataset(root, cameras=("wrist", "front"))
    for i in range(3):
        assert_start_of(dataset, i)


def test_a_view_with_fewer_frames_names_the_camera_the_episode_and_the_file(tmp_path):
    root = two_camera_writer_dataset(tmp_path)
    table = pq.read_table(root / META)
    column = "videos/observation.images.gripper/to_timestamp"
    shorter = pc.if_else(pc.equal(table["episode_index"], 1), pc.subtract(table[column], 2 / 80), table[column])
    pq.write_table(table.set_column(table.schema.get_field_index(column), column, shorter), root / META)
    dataset = EpisodeDataset(root, cameras=("front", "gripper"))
    dataset.load(0)  # the other episode is intact
    # Each camera is matched to the rows first: 7 frames for 9 rows is beyond the tolerance of one.
    with pytest.raises(DatasetError, match=rf"{GRIPPER_VIDEO}: camera 'observation.images.gripper' of episode 1 "
                                           r"has 7 frames for 9 data rows"):
        dataset.load(1)


def test_a_view_of_another_size_names_the_camera_the_episode_and_the_file(tmp_path):
    root = two_camera_writer_dataset(tmp_path / "big", size=48)
    small = two_camera_writer_dataset(tmp_path / "small", size=32)
    shutil.copyfile(small / GRIPPER_VIDEO, root / GRIPPER_VIDEO)
    with pytest.raises(DatasetError, match=r"camera 'gripper' of episode 0 has frames \(7, 32, 32, 3\) .* "
                                           r"camera 'front' has \(7, 48, 48, 3\)"):
        EpisodeDataset(root, cameras=("front", "gripper")).load(0)
    with pytest.raises(DatasetError, match=r"camera 'gripper' of episode 0 has frames \(1, 32, 32, 3\) .* "
                                           r"camera 'front' has \(1, 48, 48, 3\)"):
        EpisodeDataset(root, cameras=("front", "gripper")).first_frame(0)


def test_a_missing_view_names_the_camera_the_episode_and_the_file(tmp_path):
    root = two_camera_writer_dataset(tmp_path)
    (root / GRIPPER_VIDEO).unlink()
    with pytest.raises(DatasetError, match=rf"\(camera 'gripper'\): video file .*{GRIPPER_VIDEO} does not exist "
                                           r"\(it holds episode 0's frames\)"):
        EpisodeDataset(root, cameras=("front", "gripper"))
    with pytest.raises(DatasetError, match="no feature 'observation.images.side' for camera 'side'"):
        EpisodeDataset(root, cameras=("front", "side"))
    assert EpisodeDataset(root).load(1).frames.shape == (9, 48, 48, 3)  # the front camera alone still reads


def test_one_camera_datasets_read_as_before_with_their_camera_as_the_only_view(tmp_path):
    with LeRobotWriter(tmp_path) as writer:
        writer.add(make_episode(4, seed=0))
    dataset = EpisodeDataset(tmp_path, camera="front")
    assert dataset.cameras == ("front",) and list(dataset.available_cameras) == ["front"]
    loaded = dataset.load(0)
    assert list(loaded.views) == ["front"] and loaded.views["front"] is loaded.frames
    with pytest.raises(ValueError, match="starting with camera='front'"):
        EpisodeDataset(tmp_path, camera="front", cameras=("gripper", "front"))


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_another_robots_dataset_reads_every_camera_asked_for(tmp_path, version):
    root = write_robot_dataset(tmp_path, version=version, episodes=2, steps=5, height=24, width=32,
                               cameras=("front", "wrist"), short_video=True)
    dataset = EpisodeDataset(root, cameras=("wrist", "front"))
    assert dataset.camera_key == "wrist" and list(dataset.available_cameras) == ["front", "wrist"]
    for i in range(2):  # the last episode's videos lack a frame, each camera alike: matched as one
        views = dataset.load(i).views
        assert {name: frames.shape for name, frames in views.items()} == {"wrist": (6, 24, 32, 3), "front": (6, 24, 32, 3)}
        assert not np.array_equal(views["wrist"], views["front"])


def test_cli_collect_records_the_cameras_asked_for_and_inspect_lists_them(tmp_path, capsys):
    out = tmp_path / "data"
    main(["collect", "--tasks", "reach-v3", "--episodes-per-task", "1", "--failure-fraction", "0", "--out", str(out),
          "--workers", "1", "--env.image-size", "32", "--env.horizon", "10", "--cameras", "front,gripper"])
    main(["inspect", "--data", str(out)])
    assert "cameras: front [32, 32, 3] video, gripper [32, 32, 3] video" in capsys.readouterr().out
