"""Datasets of other robots: the camera that has frames, the action feature and its statistics, frames fitted to a square."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from robot_datasets import write_robot_dataset

from gymnast.data.action_stats import ActionStats
from gymnast.data.frames import fit_frames, model_image_size
from gymnast.data.lerobot import DatasetError, EpisodeDataset


def test_the_default_camera_is_the_first_whose_video_exists(tmp_path):
    write_robot_dataset(tmp_path, version="v2.0", cameras=("wrist", "front"), without_video=("wrist",), episodes=2, steps=3)
    dataset = EpisodeDataset(tmp_path)
    assert dataset.camera_key == "front" and dataset.load(1).frames.shape == (4, 120, 160, 3)
    missing = tmp_path / "videos/chunk-000/observation.images.wrist/episode_000000.mp4"
    with pytest.raises(DatasetError, match=re.escape(f"feature 'observation.images.wrist' (camera 'wrist'): video file {missing} does not exist")):
        EpisodeDataset(tmp_path, "wrist")


def test_no_camera_with_frames_is_an_error_naming_each_camera(tmp_path):
    write_robot_dataset(tmp_path, version="v3.0", cameras=("wrist", "front"), without_video=("wrist", "front"), episodes=2, steps=3)
    with pytest.raises(DatasetError, match="no camera has frames to read; 'observation.images.wrist': video file .* does not exist; "
                                           "'observation.images.front': video file"):
        EpisodeDataset(tmp_path)


def test_a_dataset_without_actions_is_refused_naming_the_field(tmp_path):
    write_robot_dataset(tmp_path, episodes=1, steps=3)
    info = json.loads((tmp_path / "meta/info.json").read_text())
    del info["features"]["action"]
    (tmp_path / "meta/info.json").write_text(json.dumps(info))
    with pytest.raises(DatasetError, match=re.escape(f"{tmp_path / 'meta/info.json'}: no 'action' feature in 'features'")):
        EpisodeDataset(tmp_path)


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_action_stats_are_computed_from_the_data_when_the_dataset_has_none(tmp_path, version):
    write_robot_dataset(tmp_path, version=version, action_dim=26, episodes=3, steps=4, action_scale=3.0)
    dataset = EpisodeDataset(tmp_path)
    actions = np.concatenate([dataset.load(i).actions for i in range(3)])  # (T, A) without each last row
    stats = dataset.action_stats
    assert stats.dim == 26 and stats.count == 15  # every row's action, the last ones too
    assert np.all(np.array(stats.min) <= actions.min(0)) and np.all(np.array(stats.max) >= actions.max(0))
    assert max(stats.max) > 1.0  # the robot's own units, not [-1, 1]


def test_action_stats_come_from_meta_stats_json_and_are_checked(tmp_path):
    write_robot_dataset(tmp_path, action_dim=3, episodes=1, steps=3)
    stats = {"action": {"min": [-2, -1, 0], "max": [2, 1, 0], "mean": [0, 0, 0], "std": [1, 1, 0], "count": [4]}}
    (tmp_path / "meta/stats.json").write_text(json.dumps(stats))
    loaded = EpisodeDataset(tmp_path).action_stats
    assert loaded == ActionStats((-2, -1, 0), (2, 1, 0), (0, 0, 0), (1, 1, 0), count=4)
    assert loaded.action_range() == ((-2, -1, -1), (2, 1, 1))  # a dimension that never moves gets a range
    stats["action"]["min"] = [-2, -1]
    (tmp_path / "meta/stats.json").write_text(json.dumps(stats))
    with pytest.raises(DatasetError, match=re.escape(f"{tmp_path / 'meta/stats.json'}: field 'action.min' is [-2, -1], expected 3")):
        EpisodeDataset(tmp_path).action_stats


def test_actions_narrower_than_the_feature_are_an_error_naming_file_and_field(tmp_path):
    write_robot_dataset(tmp_path, action_dim=7, episodes=1, steps=3)
    info = json.loads((tmp_path / "meta/info.json").read_text())
    info["features"]["action"]["shape"] = [8]
    (tmp_path / "meta/info.json").write_text(json.dumps(info))
    data = tmp_path / "data/chunk-000/episode_000000.parquet"
    with pytest.raises(DatasetError, match=re.escape(f"{data}: field 'action' has 7 values per row, info.json's 'action' feature says 8")):
        EpisodeDataset(tmp_path).action_stats


def test_square_frames_a_model_can_take_set_its_size_and_others_get_the_presets():
    assert model_image_size((96, 96, 3), 64) == 96  # Meta-World's frames, as before
    assert model_image_size((32, 32, 3), 96) == 32
    assert [model_image_size(shape, 96) for shape in [(120, 160, 3), (480, 640, 3), (480, 480, 3), (84, 84, 3)]] == [96] * 4


def test_resize_keeps_the_whole_frame_and_crop_its_central_square():
    frames = np.zeros((2, 40, 80, 3), np.uint8)
    frames[:, :, :20] = 255  # a white band on the left quarter, outside the central square
    resized, cropped = fit_frames(frames, 16, "resize"), fit_frames(frames, 16, "crop")
    assert resized.shape == cropped.shape == (2, 16, 16, 3)
    assert resized[:, :, :3].min() == 255 and cropped.max() == 0
    np.testing.assert_array_equal(fit_frames(frames, 40, "crop"), frames[:, :, 20:60])  # the square, not resized
    assert fit_frames(resized, 16, "resize") is resized  # frames of the size asked are left alone
    with pytest.raises(ValueError, match="fit must be one of"):
        fit_frames(frames, 16, "pad")


def test_a_fitted_dataset_loads_square_frames_of_the_size_asked(tmp_path):
    write_robot_dataset(tmp_path, version="v3.0", episodes=2, steps=3, short_video=True)
    dataset = EpisodeDataset(tmp_path)
    fitted = dataset.fitted(48, "crop")
    assert (dataset.image_shape, fitted.image_shape, fitted.camera_shape) == ((120, 160, 3), (48, 48, 3), (120, 160, 3))
    episode = fitted.load(1)  # its video is one frame short: the last row reuses the last frame
    assert episode.frames.shape == (4, 48, 48, 3) and episode.states.shape == (4, 7)
