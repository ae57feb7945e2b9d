"""Episode datasets in the LeRobot format: read v3.0 (what gymnast writes) and v2.0 / v2.1.

    writer = LeRobotWriter("data/demo")      # v3.0; see gymnast.data.lerobot_writer
    writer.add(episode); writer.flush()
    dataset = EpisodeDataset("data/demo")
    episode = dataset.load(0)                # frames (T+1, H, W, 3) uint8, actions (T, A), ...

Datasets made elsewhere have no ``gymnast/...`` episode columns; their `EpisodeInfo` gets the
defaults documented in `gymnast.data.lerobot_format.episode_info`. ``docs/dataset_format.md``
describes the layout.

Legend: T steps of an episode, H/W image height/width, A action dimensions.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pyarrow as pa

from gymnast.data import lerobot_v3, lerobot_v21
from gymnast.data.lerobot_format import (
    DatasetError,
    EpisodeRef,
    assemble_episode,
    column_vector,
    decode_images,
    episode_info,
    has_info_columns,
    image_key,
    read_parquet,
)
from gymnast.data.lerobot_writer import LeRobotWriter
from gymnast.data.schema import Episode, EpisodeInfo
from gymnast.utils.video import decode_video

__all__ = ["SUPPORTED_VERSIONS", "DatasetError", "EpisodeDataset", "LeRobotWriter"]

SUPPORTED_VERSIONS = (*lerobot_v21.CODEBASE_VERSIONS, lerobot_v3.CODEBASE_VERSION)
_CACHED_DATA_FILES = 2  # a v3.0 data file holds many episodes: keep the last ones read


class EpisodeDataset:
    """The episodes of a LeRobot dataset, loaded one at a time as `Episode` objects.

    Args:
        root: dataset directory (the one holding ``meta/info.json``).
        camera: camera to read, e.g. ``front``; default: the first video feature, else the first
            image feature.

    Attributes:
        root: dataset directory.
        info: the parsed ``meta/info.json``.
        version: its ``codebase_version``.
        fps: frames per second.
        image_key: the camera feature read, e.g. ``observation.images.front``.
        camera_key: the camera name, e.g. ``front``.
        image_shape: (H, W, 3) of the frames.

    Raises:
        FileNotFoundError: ``meta/info.json`` or a metadata file is missing.
        DatasetError: unsupported ``codebase_version`` or malformed metadata (names file and field).
    """

    def __init__(self, root: str | Path, camera: str | None = None) -> None:
        self.root = Path(root)
        info_path = self.root / lerobot_v3.INFO_PATH
        self.info = lerobot_v3.load_info(self.root)
        self.version = self.info.get("codebase_version")
        if self.version not in SUPPORTED_VERSIONS:
            supported = ", ".join(SUPPORTED_VERSIONS)
            raise DatasetError(
                f"{info_path}: codebase_version {self.version!r} is not supported (supported: {supported})"
            )
        features = lerobot_v3.info_field(self.info, "features", dict, info_path)
        self.fps = lerobot_v3.info_field(self.info, "fps", (int, float), info_path)
        self.image_key = _camera_feature(features, camera, info_path)
        self.camera_key = self.image_key.removeprefix("observation.images.")
        self.image_shape = _image_shape(features[self.image_key], self.image_key, info_path)
        reader = lerobot_v3 if self.version == lerobot_v3.CODEBASE_VERSION else lerobot_v21
        self._refs: list[EpisodeRef] = reader.episode_refs(self.root, self.info, self.image_key)
        self._tables: OrderedDict[Path, pa.Table] = OrderedDict()

    def __len__(self) -> int:
        return len(self._refs)

    @property
    def lengths(self) -> list[int]:
        """Number of steps T of each episode (it has T + 1 frames)."""
        return [ref.length - 1 for ref in self._refs]

    @functools.cached_property
    def episodes(self) -> list[EpisodeInfo]:
        """Per-episode facts, in episode order (for other datasets this reads ``next.success``)."""
        return [self._info(ref) for ref in self._refs]

    def load(self, i: int) -> Episode:
        """Decode episode ``i``: its frames, states, actions, rewards and successes.

        Raises:
            IndexError: no episode ``i``.
            FileNotFoundError: its data or video file is missing.
            DatasetError: a file is unreadable or truncated, or a field is missing or of the
                wrong type; the message names the file and field.
        """
        if not 0 <= i < len(self._refs):
            raise IndexError(f"episode {i} is out of range: {self.root} has {len(self._refs)} episodes")
        ref = self._refs[i]
        rows = self._rows(ref)
        if ref.video_path is None:
            frames = decode_images(rows, self.image_key, ref.data_path)
        else:
            try:
                # One frame of tolerance, as LeRobot's timestamp matching has; `assemble_episode`
                # pairs the frames with the rows and warns.
                frames = decode_video(ref.video_path, *ref.video_span, may_lack=1)
            except ValueError as e:
                raise DatasetError(f"episode {ref.index}, field {self.image_key!r}: {e}") from e
        return assemble_episode(ref, rows, frames)

    def _info(self, ref: EpisodeRef) -> EpisodeInfo:
        if has_info_columns(list(ref.columns)) or "next.success" not in self.info["features"]:
            return episode_info(ref, None)
        return episode_info(ref, column_vector(self._rows(ref), "next.success", ref.data_path, bool))

    def _rows(self, ref: EpisodeRef) -> pa.Table:
        """The episode's rows of its data file (the last files read stay cached)."""
        table = self._tables.pop(ref.data_path, None)
        if table is None:
            table = read_parquet(ref.data_path)
        self._tables[ref.data_path] = table
        while len(self._tables) > _CACHED_DATA_FILES:
            self._tables.popitem(last=False)
        if ref.rows is not None:
            index = column_vector(table, "index", ref.data_path, np.int64)
            table = table.filter(pa.array((index >= ref.rows[0]) & (index < ref.rows[1])))
        if table.num_rows != ref.length:
            raise DatasetError(
                f"{ref.data_path}: episode {ref.index} should have {ref.length} rows "
                f"(per {ref.meta_path}), found {table.num_rows}"
            )
        return table


def _camera_feature(features: dict, camera: str | None, info_path: Path) -> str:
    if camera is not None:
        if image_key(camera) not in features:
            raise DatasetError(f"{info_path}: no feature {image_key(camera)!r} for camera {camera!r}")
        return image_key(camera)
    for dtype in ("video", "image"):
        keys = [k for k, f in features.items() if isinstance(f, dict) and f.get("dtype") == dtype]
        if keys:
            return keys[0]
    raise DatasetError(f"{info_path}: no feature of dtype 'video' or 'image' in 'features'")


def _image_shape(feature: dict, key: str, info_path: Path) -> tuple[int, int, int]:
    """(H, W, 3) from a feature's shape, which some datasets give channels-first."""
    shape, names = feature.get("shape"), feature.get("names") or []
    if not (isinstance(shape, list) and len(shape) == 3 and all(isinstance(s, int) for s in shape)):
        raise DatasetError(f"{info_path}: features[{key!r}].shape is {shape!r}, expected [H, W, 3]")
    if names and names[0] in ("channel", "channels"):
        shape = [shape[1], shape[2], shape[0]]
    return tuple(shape)
