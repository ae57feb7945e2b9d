"""Bad input: every error names the file and the field (and both values where two disagree)."""

from __future__ import annotations

import json
import re

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from data_helpers import make_episode

from gymnast.data.lerobot import DatasetError, EpisodeDataset, LeRobotWriter

DATA = "data/chunk-000/file-000.parquet"
VIDEO = "videos/observation.images.front/chunk-000/file-000.mp4"
META = "meta/episodes/chunk-000/file-000.parquet"


@pytest.fixture
def dataset_dir(tmp_path):
    with LeRobotWriter(tmp_path) as writer:
        writer.add(make_episode(6, seed=0))
        writer.add(make_episode(8, seed=1))
    return tmp_path


def truncate(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def rewrite_parquet(path, change):
    pq.write_table(change(pq.read_table(path)), path)


def test_truncated_parquet_names_the_file(dataset_dir):
    truncate(dataset_dir / DATA)
    dataset = EpisodeDataset(dataset_dir)
    with pytest.raises(DatasetError, match=re.escape(f"{dataset_dir / DATA}: cannot read parquet")):
        dataset.load(0)


def test_truncated_video_names_the_file(dataset_dir):
    truncate(dataset_dir / VIDEO)
    with pytest.raises(DatasetError, match=re.escape(str(dataset_dir / VIDEO))):
        EpisodeDataset(dataset_dir).load(1)


def test_missing_video_names_the_file_when_the_dataset_is_opened(dataset_dir):
    (dataset_dir / VIDEO).unlink()
    with pytest.raises(DatasetError, match=re.escape(f"video file {dataset_dir / VIDEO} does not exist")):
        EpisodeDataset(dataset_dir)


def test_missing_data_field_names_field_and_file(dataset_dir):
    rewrite_parquet(dataset_dir / DATA, lambda t: t.drop_columns(["action"]))
    with pytest.raises(
        DatasetError, match=re.escape(f"{dataset_dir / DATA}: field 'action' is missing")
    ):
        EpisodeDataset(dataset_dir).load(0)


def test_wrong_typed_data_field_names_field_and_file(dataset_dir):
    def action_as_text(table):
        i = table.column_names.index("action")
        return table.set_column(i, "action", pa.array([str(v) for v in table.column("action").to_pylist()]))

    rewrite_parquet(dataset_dir / DATA, action_as_text)
    with pytest.raises(
        DatasetError, match=re.escape(f"{dataset_dir / DATA}: field 'action' has type string")
    ):
        EpisodeDataset(dataset_dir).load(0)


def test_missing_or_wrong_typed_episode_field_names_field_and_file(dataset_dir):
    path = dataset_dir / META
    original = pq.read_table(path)
    pq.write_table(original.drop_columns(["dataset_to_index"]), path)
    with pytest.raises(DatasetError, match=re.escape(f"{path}: field 'dataset_to_index' is missing")):
        EpisodeDataset(dataset_dir)
    i = original.column_names.index("gymnast/seed")
    pq.write_table(original.set_column(i, "gymnast/seed", pa.array(["zero", "one"])), path)
    with pytest.raises(DatasetError, match=re.escape(f"{path}: field 'gymnast/seed' has type string")):
        EpisodeDataset(dataset_dir)


def test_shape_mismatch_on_add_names_the_feature_and_both_shapes(tmp_path):
    writer = LeRobotWriter(tmp_path)
    writer.add(make_episode(4, seed=0))
    with pytest.raises(ValueError, match=r"observation\.state: the dataset has shape \(4,\), .* has \(5,\)"):
        writer.add(make_episode(4, seed=1, state_dim=5))
    with pytest.raises(
        ValueError,
        match=r"observation\.images\.front: the dataset has shape \(48, 48, 3\), .* \(32, 32, 3\)",
    ):
        writer.add(make_episode(4, seed=2, size=32))
    writer.flush()
    with pytest.raises(ValueError, match=r"observation\.environment_state: the dataset has shape \(39,\)"):
        LeRobotWriter(tmp_path).add(make_episode(4, seed=3, env_dim=7))


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ({"fps": 30}, "fps is 80 in the dataset but the writer was given 30"),
        (
            {"camera": "side"},
            r"camera is \['front'\] in the dataset but the writer was given \['side'\]",
        ),
        ({"robot_type": "ur5"}, "robot_type is 'sawyer' in the dataset but the writer was given 'ur5'"),
    ],
)
def test_reopening_with_other_settings_names_the_field_and_both_values(dataset_dir, option, message):
    with pytest.raises(ValueError, match=message):
        LeRobotWriter(dataset_dir, **option)


def test_unsupported_version_lists_the_supported_ones(dataset_dir):
    path = dataset_dir / "meta/info.json"
    info = json.loads(path.read_text())
    path.write_text(json.dumps(info | {"codebase_version": "v1.6"}))
    with pytest.raises(
        DatasetError,
        match=re.escape("codebase_version 'v1.6' is not supported (supported: v2.0, v2.1, v3.0)"),
    ):
        EpisodeDataset(dataset_dir)


def test_missing_dataset_names_info_json(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"meta/info\.json"):
        EpisodeDataset(tmp_path)


def test_data_rows_that_disagree_with_the_episode_index_are_reported(dataset_dir):
    rewrite_parquet(dataset_dir / DATA, lambda t: t.slice(0, 10))
    with pytest.raises(
        DatasetError, match=re.escape(f"{dataset_dir / DATA}: episode 1 should have 9 rows") + ".* found 3"
    ):
        EpisodeDataset(dataset_dir).load(1)
