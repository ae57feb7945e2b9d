"""Datasets as people publish them: features named ``actions``, ``state`` and ``image`` are read with
--action-key, --state-key and --camera, and until then every error and `inspect` say which flags to pass."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from robot_datasets import TASKS, write_robot_dataset

from gymnast.cli import main
from gymnast.data.features import FeatureNotFound
from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.rl.inputs import policy_frames, policy_keys
from gymnast.rl.rollout import dataset_starts, own_tasks
from gymnast.world_model.train import saved_train_config

PUBLISHED = {"action": "actions", "observation.state": "state", "observation.images.front": "image"}
"""How a published dataset may name LeRobot's features."""
THEIR_KEYS = FeatureKeys(action_key="actions", state_key="state")
THEIR_FLAGS = ["--action-key", "actions", "--state-key", "state", "--camera", "image"]


def rename_features(root: Path, renames: dict[str, str]) -> Path:
    """Rename features of a written dataset everywhere they appear: ``info.json``, the data files'
    columns, the episode index's video columns and the video folders."""
    info_path = root / "meta/info.json"
    info = json.loads(info_path.read_text())
    info["features"] = {renames.get(key, key): feature for key, feature in info["features"].items()}
    info_path.write_text(json.dumps(info))

    def renamed(column: str) -> str:
        for old, new in renames.items():
            if column == old or column.startswith(f"videos/{old}/"):
                return column.replace(old, new, 1)
        return column

    for path in [*(root / "data").rglob("*.parquet"), *(root / "meta/episodes").rglob("*.parquet")]:
        table = pq.read_table(path)
        pq.write_table(table.rename_columns([renamed(name) for name in table.column_names]), path)
    for old, new in renames.items():
        for folder in list((root / "videos").rglob(old)):
            folder.rename(folder.with_name(new))
    return root


def published(root: Path, version: str = "v3.0", episodes: int = 2, steps: int = 3) -> Path:
    """A small dataset of another robot (7-D actions and states, 24x32 frames) with published names."""
    data = write_robot_dataset(root, version=version, episodes=episodes, steps=steps, height=24, width=32)
    return rename_features(data, PUBLISHED)


@pytest.mark.parametrize("version", ["v3.0", "v2.1"])
def test_a_dataset_with_other_feature_names_loads_with_its_keys_as_with_lerobots(version, tmp_path):
    theirs = EpisodeDataset(published(tmp_path / "theirs", version), camera="image", keys=THEIR_KEYS)
    ours = EpisodeDataset(write_robot_dataset(tmp_path / "ours", version=version, episodes=2, steps=3, height=24, width=32))
    assert (theirs.action_dim, theirs.camera_key, theirs.image_key) == (7, "image", "image")
    for name in ("actions", "states", "frames"):
        np.testing.assert_array_equal(getattr(theirs.load(1), name), getattr(ours.load(1), name), err_msg=name)
    assert theirs.action_stats == ours.action_stats


def test_the_missing_action_feature_names_the_file_the_candidates_and_the_flag(tmp_path):
    data = published(tmp_path)
    message = (f"{data / 'meta/info.json'}: no 'action' feature in 'features'; candidates: 'actions' (float32, 7), "
               "'state' (float32, 7) - pass --action-key actions")
    with pytest.raises(FeatureNotFound, match=re.escape(message)):
        EpisodeDataset(data)
    with pytest.raises(FeatureNotFound, match=re.escape("no 'proprio' feature in 'features'; candidates: "
                                                        "'state' (float32, 7) - pass --state-key state")):
        EpisodeDataset(data, keys=FeatureKeys("actions", "proprio"))  # a state key asked for must be there
    with pytest.raises(FeatureNotFound, match=re.escape("no feature 'observation.images.top' for camera 'top'; "
                                                        "candidates: 'image' (video, 24x32x3) - pass --camera image")):
        EpisodeDataset(data, camera="top", keys=THEIR_KEYS)


def test_a_camera_is_picked_by_its_name_or_its_whole_feature_key(tmp_path):
    data = write_robot_dataset(tmp_path, version="v3.0", episodes=2, steps=3, height=24, width=32, cameras=("wrist", "front"))
    by_key = EpisodeDataset(data, camera="observation.images.front")
    assert (by_key.camera_key, by_key.image_key) == ("front", "observation.images.front")
    np.testing.assert_array_equal(by_key.load(0).frames, EpisodeDataset(data, camera="front").load(0).frames)
    both = EpisodeDataset(data, cameras=("observation.images.front", "wrist"))
    assert both.cameras == ("front", "wrist") and set(both.load(0).views) == {"front", "wrist"}


def test_inspect_lists_the_candidates_and_the_flags_instead_of_failing(tmp_path, capsys):
    data = published(tmp_path)
    main(["inspect", "--data", str(data)])
    out = capsys.readouterr().out
    assert "action (float vectors; 'action' is missing): 'actions' (float32, 7), 'state' (float32, 7)" in out
    assert "state (float vectors; 'observation.state' is missing): 'state' (float32, 7)" in out
    assert "camera (image or video features): 'image' (video, 24x32x3)" in out
    assert out.strip().endswith("pass: --action-key actions --state-key state")

    main(["inspect", "--data", str(data), *THEIR_FLAGS])
    out = capsys.readouterr().out
    assert "from camera 'image', 7-D actions" in out
    assert "actions: 'actions' (float32, 7); states: 'state' (float32, 7)" in out


def test_inspect_says_which_feature_could_be_the_states_it_would_leave_empty(tmp_path, capsys):
    data = rename_features(write_robot_dataset(tmp_path, version="v3.0", episodes=2, steps=3, height=24, width=32),
                           {"observation.state": "state"})
    main(["inspect", "--data", str(data)])
    assert "states: none (no 'observation.state'; candidates: 'state' (float32, 7) - pass --state-key state)" \
        in capsys.readouterr().out


def test_a_command_on_an_unmapped_dataset_stops_naming_the_flag(tmp_path, capsys):
    data = published(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(["sft", "--data", str(data), "--out", str(tmp_path / "sft"), "--preset", "debug"])
    error = capsys.readouterr().err
    assert exit_info.value.code == 2 and "Traceback" not in error
    assert f"{data / 'meta/info.json'}: no 'action' feature in 'features'" in error and "pass --action-key actions" in error


def test_train_wm_reads_the_dataset_by_its_keys_and_saves_them_with_the_run(tmp_path, capsys):
    data, out = published(tmp_path / "data", episodes=4, steps=8), tmp_path / "wm"
    main(["train-wm", "--data", str(data), "--out", str(out), "--preset", "debug", "--steps", "2", *THEIR_FLAGS])
    saved = saved_train_config(out)
    assert (saved.keys, saved.camera) == (THEIR_KEYS, "image")
    assert json.loads((out / "config.json").read_text())["train"]["keys"] == {"action_key": "actions", "state_key": "state"}
    with pytest.raises(SystemExit):  # --resume continues with the keys saved, and refuses others
        main(["train-wm", "--out", str(out), "--resume", "--action-key", "action"])
    assert "--action-key action disagrees with the run" in capsys.readouterr().err


@pytest.mark.slow
def test_rl_reads_the_start_states_by_the_keys_the_policy_was_trained_with(tmp_path, capsys):
    data, out = published(tmp_path / "data", episodes=4, steps=8), tmp_path / "sft"
    main(["sft", "--data", str(data), "--out", str(out), "--preset", "debug", "--steps", "2", *THEIR_FLAGS])
    assert policy_keys(out) == THEIR_KEYS and policy_frames(out)["camera"] == "image"
    starts = dataset_starts(data, own_tasks(data, keys=THEIR_KEYS), keys=THEIR_KEYS)
    assert {start.task for start in starts} == set(TASKS) and starts[0].frames.shape[-3:] == (24, 32, 3)
    capsys.readouterr()
