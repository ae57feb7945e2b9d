"""Episode datasets in the LeRobot format: read v3.0 (what gymnast writes) and v2.0 / v2.1.

    writer = LeRobotWriter("data/demo")      # v3.0; see gymnast.data.lerobot_writer
    writer.add(episode); writer.flush()
    dataset = EpisodeDataset("data/demo")
    episode = dataset.load(0)                # frames (T+1, H, W, 3) uint8, actions (T, A), ...
    square = dataset.fitted(96, "crop")      # the same episodes with 96 x 96 frames (gymnast.data.frames)
    both = EpisodeDataset("data/demo", cameras=("front", "gripper"))
    both.load(0).views["gripper"]            # (T+1, H, W, 3) uint8; views["front"] is frames
    both.first_frame(0)                      # (H, 2W, 3): both views' first frames, decoded alone
    both.frames(0, 10, 12)                   # (2, H, 2W, 3): frames 10 and 11, decoded alone
    both.columns(0).actions                  # (T, A): load's vectors and facts, no frame decoded
    theirs = EpisodeDataset("data/x", camera="image", keys=FeatureKeys("actions", "state"))

Datasets made elsewhere have no ``gymnast/...`` episode columns; their `EpisodeInfo` gets the
defaults documented in `gymnast.data.lerobot_format.episode_info`, and their features may be named
otherwise (`gymnast.data.features`). ``docs/dataset_format.md`` describes the layout.

Legend: T steps of an episode, H/W image height/width, A action dimensions.
"""

from __future__ import annotations

import copy
import functools
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from gymnast.data import lerobot_v3, lerobot_v21
from gymnast.data.action_stats import ActionStats, read_action_stats
from gymnast.data.deviations import Deviations, check_rows
from gymnast.data.features import camera_features, camera_key, camera_name, image_shape, vector_width
from gymnast.data.frames import Fit, fit_frames
from gymnast.data.lerobot_format import (
    DatasetError,
    EpisodeRef,
    FeatureKeys,
    assemble_episode,
    column_vector,
    episode_columns,
    episode_info,
    has_info_columns,
    read_parquet,
)
from gymnast.data.lerobot_frames import decode_episode, decode_range, lacking_frames
from gymnast.data.lerobot_writer import LeRobotWriter
from gymnast.data.schema import Episode, EpisodeColumns, EpisodeInfo
from gymnast.utils.images import tile_views

__all__ = ["SUPPORTED_VERSIONS", "DatasetError", "EpisodeDataset", "FeatureKeys", "LeRobotWriter"]

SUPPORTED_VERSIONS = (*lerobot_v21.CODEBASE_VERSIONS, lerobot_v3.CODEBASE_VERSION)
_CACHED_DATA_FILES = 2  # a v3.0 data file holds many episodes: keep the last ones read


class EpisodeDataset:
    """The episodes of a LeRobot dataset, loaded one at a time as `Episode` objects.

    Args:
        root: dataset directory (the one holding ``meta/info.json``).
        camera: camera to read, by name (``front`` is ``observation.images.front``) or by feature key
            (``image``, ``observation.images.top``); default: the first camera whose frames exist (a
            video feature with its video files, else an image feature with its column).
        cameras: several cameras to read, named as `camera`, e.g. ``("front", "gripper")``: the first is the primary
            (`Episode.frames`, and `camera` if given must be it), and `Episode.views` holds them all.
            Their frames must have one size and, in every episode, one count. Default: `camera`.
        keys: which features are the actions and the states (default: LeRobot's ``action`` and
            ``observation.state``).

    Attributes:
        root: dataset directory.
        info: the parsed ``meta/info.json``.
        version: its ``codebase_version``.
        fps: frames per second.
        image_key: the camera feature read, e.g. ``observation.images.front`` or ``image``.
        camera_key: the camera name, e.g. ``front`` (`gymnast.data.features.camera_name`).
        cameras: the names of the cameras read, the primary first (`Episode.views` has each).
        available_cameras: every camera of the dataset, name -> feature (video ones, then image ones).
        keys: the features read as the actions and the states.
        camera_shape: (H, W, 3) of the camera's frames as stored.
        image_shape: (H, W, 3) of the frames `load` returns: `camera_shape`, or square once `fitted`.
        action_dim: width A of the action feature.
        deviations: where the dataset departs from the LeRobot specification and what reading it
            assumed (`gymnast.data.deviations`), as met so far: opening it finds those of its
            metadata, reading episodes those of their files.

    Raises:
        FileNotFoundError: ``meta/info.json`` or a metadata file is missing.
        DatasetError: unsupported ``codebase_version``, malformed metadata, no camera with frames,
            or a camera asked for that has none or another frame size than the first (the message
            names the camera and the file or field).
        FeatureNotFound: no action feature, no state feature of a key asked for, or no camera asked
            for (the message lists the candidates and the flag to pass).
        ValueError: `cameras` is empty, names a camera twice or does not start with `camera`.
    """

    def __init__(self, root: str | Path, camera: str | None = None, cameras: Sequence[str] | None = None,
                 keys: FeatureKeys = FeatureKeys()) -> None:
        self.root, self.keys, self.deviations = Path(root), keys, Deviations()
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
        if not 0 < self.fps < 10_000:
            raise DatasetError(f"{info_path}: field 'fps' is {self.fps!r}, expected the frame rate of the rows and videos")
        self.action_dim = vector_width(features, keys.action_key, "action", info_path)
        if not (keys.reads_default_state and keys.state_key not in features):  # LeRobot's may be absent
            vector_width(features, keys.state_key, "state", info_path, taken=(keys.action_key,))
        names = _check_cameras(camera, cameras)
        self.image_key, self._refs = self._camera_refs(features, names[0] if names else None, info_path)
        self.camera_key = camera_name(self.image_key)
        if not self._refs:
            raise DatasetError(f"{self.root}: the dataset has no episodes (its episode metadata lists none)")
        self.camera_shape = image_shape(features[self.image_key], self.image_key, info_path, self.deviations)
        self.image_shape = self.camera_shape
        view_keys = [camera_key(features, name, info_path) for name in names[1:]]
        self.cameras = (self.camera_key, *map(camera_name, view_keys))
        self._camera_features = dict(zip(self.cameras, (self.image_key, *view_keys), strict=True))
        self.available_cameras = {camera_name(key): key for key in camera_features(features)}
        self._view_refs = {camera_name(key): self._named_refs(key, name) for key, name in zip(view_keys, names[1:])}
        for name, key in zip(self.cameras[1:], view_keys):
            shape = image_shape(features[key], key, info_path, self.deviations)
            if shape != self.camera_shape:
                raise DatasetError(f"{info_path}: camera {name!r} has frames of shape {shape} but camera "
                                   f"{self.camera_key!r} has {self.camera_shape}; cameras read together need one "
                                   "size: read one of them (--camera NAME)")
        self._fit: tuple[int, Fit] | None = None
        self._tables: OrderedDict[Path, pa.Table] = OrderedDict()
        self._checked: set[Path] = set()  # data files checked for deviations (shared with `fitted` copies)

    def fitted(self, size: int, fit: Fit) -> EpisodeDataset:
        """The same dataset, its frames fitted to `size` x `size` by `fit` (`gymnast.data.frames.fit_frames`)."""
        dataset = copy.copy(self)
        dataset._tables = OrderedDict()
        dataset._fit, dataset.image_shape = (size, fit), (size, size, 3)
        return dataset

    def __len__(self) -> int:
        return len(self._refs)

    @property
    def lengths(self) -> list[int]:
        """Number of steps T of each episode (it has T + 1 frames)."""
        return [ref.length - 1 for ref in self._refs]

    @functools.cached_property
    def action_stats(self) -> ActionStats:
        """Statistics of the actions, from ``meta/stats.json`` or else from the data files.

        Raises:
            DatasetError: the stats file or a data file lacks the action field or has the wrong width.
        """
        return read_action_stats(self.root, self.action_dim, (ref.data_path for ref in self._refs), self.keys.action_key)

    @functools.cached_property
    def episodes(self) -> list[EpisodeInfo]:
        """Per-episode facts, in episode order (for other datasets this reads ``next.success``)."""
        return [self._info(ref) for ref in self._refs]

    def load(self, i: int) -> Episode:
        """Decode episode ``i``: its frames (each camera's in `views`), states, actions, rewards and successes.

        Raises:
            IndexError: no episode ``i``.
            FileNotFoundError: its data or video file is missing.
            DatasetError: a file is unreadable or truncated, a field is missing or of the wrong
                type (the message names the file and field), or a camera's frames differ in count
                or size from the primary's (it names the camera, the episode and the file).
        """
        ref, rows, refs = self._episode(i)
        # Each camera's frames matched to the rows (`gymnast.data.lerobot_frames`), then fitted.
        views = {name: decode_episode(refs[name], rows, key, self.fps, self.deviations)
                 for name, key in self._camera_features.items()}
        _check_views(views, refs)
        if self._fit is not None:
            views = {name: fit_frames(frames, *self._fit) for name, frames in views.items()}
        return assemble_episode(ref, rows, views[self.camera_key], views, self.keys)

    def columns(self, i: int) -> EpisodeColumns:
        """Episode ``i``'s states, actions, rewards, successes and facts, as `load` gives them,
        without decoding a frame.

        Raises:
            IndexError, FileNotFoundError, DatasetError: as `load`, for its data file.
        """
        ref, rows, _ = self._episode(i)
        return episode_columns(ref, rows, self.keys)

    def first_frame(self, i: int) -> np.ndarray:
        """(H, V*W, 3) uint8 episode ``i``'s first frame of every camera read, as
        `load(i).observed_frames[0]`, decoding that frame alone: a start state needs no more, and a
        long episode's video costs seconds to decode whole."""
        return self.frames(i, 0, 1)[0]

    def frames(self, i: int, first: int, stop: int) -> np.ndarray:
        """(stop - first, H, V*W, 3) uint8 frames ``first`` to ``stop - 1`` of episode ``i``, every
        camera read fitted and side by side as in `load(i).observed_frames[first:stop]`, decoding
        those frames alone (a video from its key frame at or before ``first``): a keyframe start
        needs a few frames of its episode.

        Raises:
            IndexError: no episode ``i``, or a range outside its frames.
            FileNotFoundError, DatasetError: as `load` (a camera's frames of another count or size
                than the primary's name the camera, the episode and the file).
        """
        _, rows, refs = self._episode(i)
        if not 0 <= first < stop <= rows.num_rows:
            raise IndexError(f"frames [{first}, {stop}) are outside episode {i} of {self.root}, "
                             f"which has {rows.num_rows} frames")
        views = {name: decode_range(refs[name], rows, key, self.fps, first, stop, self.deviations)
                 for name, key in self._camera_features.items()}
        _check_views(views, refs)
        if self._fit is not None:
            views = {name: fit_frames(frames, *self._fit) for name, frames in views.items()}
        return tile_views(list(views.values()))

    def video_files(self, key: str) -> list[Path]:
        """The video file of each episode of camera feature `key` (any camera of the dataset, read or not).

        Raises:
            DatasetError: the camera's files cannot be located.
        """
        refs = self._reader.episode_refs(self.root, self.info, key, Deviations())
        return [ref.video_path for ref in refs if ref.video_path is not None]

    def _episode(self, i: int) -> tuple[EpisodeRef, pa.Table, dict[str, EpisodeRef]]:
        """Episode ``i``'s reference, its data rows and every camera's reference by name."""
        if not 0 <= i < len(self._refs):
            raise IndexError(f"episode {i} is out of range: {self.root} has {len(self._refs)} episodes")
        ref = self._refs[i]
        refs = {self.camera_key: ref} | {name: view_refs[i] for name, view_refs in self._view_refs.items()}
        return ref, self._rows(ref), refs

    def _camera_refs(self, features: dict, camera: str | None, info_path: Path) -> tuple[str, list[EpisodeRef]]:
        """The camera feature to read and its episodes: the one asked for, or the first with frames.

        Raises:
            DatasetError: the camera asked for is not a feature or has no frames, or no camera has
                any (the message names each camera and what it lacks).
        """
        if camera is not None:
            key = camera_key(features, camera, info_path)
            return key, self._named_refs(key, camera)
        reasons, errors = [], []
        for key in camera_features(features):
            try:
                refs = self._reader.episode_refs(self.root, self.info, key, self.deviations)
            except DatasetError as e:
                reasons.append(f"{key!r}: {e}")
                errors.append(e)
                continue
            lacking = lacking_frames(refs, key)
            if not lacking:
                return key, refs
            reasons.append(f"{key!r}: {lacking}")
        if not reasons:
            raise DatasetError(f"{info_path}: no feature of dtype 'video' or 'image' in 'features'; a camera is a "
                               "feature of dtype 'video' (mp4 files) or 'image' (images in the rows)")
        if len(errors) == len(reasons) and len({str(e).replace(repr(k), "") for e, k in
                                                 zip(errors, camera_features(features))}) == 1:
            raise errors[0]  # the episode list itself, not any camera: say it as it is
        raise DatasetError(f"{self.root}: no camera has frames to read; " + "; ".join(reasons))

    def _named_refs(self, key: str, camera: str) -> list[EpisodeRef]:
        """The episodes of camera feature `key`, asked for as `camera`.

        Raises:
            DatasetError: the camera lacks frames (the message names the camera and what it lacks).
        """
        refs = self._reader.episode_refs(self.root, self.info, key, self.deviations)
        lacking = lacking_frames(refs, key)
        if lacking:
            missing = [ref.index for ref in refs if ref.video_path is not None and not ref.video_path.is_file()]
            episode = f" (it holds episode {missing[0]}'s frames)" if missing else ""
            raise DatasetError(f"feature {key!r} (camera {camera!r}): {lacking}{episode}")
        return refs

    @property
    def _reader(self):
        """The module that locates episodes in this dataset's layout."""
        return lerobot_v3 if self.version == lerobot_v3.CODEBASE_VERSION else lerobot_v21

    def _info(self, ref: EpisodeRef) -> EpisodeInfo:
        if has_info_columns(list(ref.columns)) or "next.success" not in self.info["features"]:
            return episode_info(ref, None)
        return episode_info(ref, column_vector(self._rows(ref), "next.success", ref.data_path, bool))

    def _rows(self, ref: EpisodeRef) -> pa.Table:
        """The episode's rows of its data file (the last files read stay cached; a file is checked for
        deviations once, the first time it is read, `gymnast.data.deviations.check_rows`)."""
        table = self._tables.pop(ref.data_path, None)
        if table is None:
            table = read_parquet(ref.data_path)
            if ref.data_path not in self._checked:
                check_rows(table, ref.data_path, self.fps, self.info["features"], self.deviations)
                self._checked.add(ref.data_path)
        self._tables[ref.data_path] = table
        while len(self._tables) > _CACHED_DATA_FILES:
            self._tables.popitem(last=False)
        if ref.rows is not None:
            table = _episode_rows(table, ref)
        if table.num_rows != ref.length:
            raise DatasetError(
                f"{ref.data_path}: episode {ref.index} should have {ref.length} rows "
                f"(per {ref.meta_path}), found {table.num_rows}"
            )
        return table


def _episode_rows(table: pa.Table, ref: EpisodeRef) -> pa.Table:
    """An episode's rows of a shared (v3.0) data file: by the global ``index`` LeRobot writes, else
    (a file without it) by ``episode_index``.

    Raises:
        DatasetError: the file has neither column.
    """
    if "index" in table.column_names:
        index = column_vector(table, "index", ref.data_path, np.int64)
        return table.filter(pa.array((index >= ref.rows[0]) & (index < ref.rows[1])))
    if "episode_index" in table.column_names:
        return table.filter(pa.array(column_vector(table, "episode_index", ref.data_path, np.int64) == ref.index))
    raise DatasetError(f"{ref.data_path}: fields 'index' and 'episode_index' are both missing, so the rows of episode "
                       f"{ref.index} cannot be told apart in a file shared by several episodes; add either column")


def _check_cameras(camera: str | None, cameras: Sequence[str] | None) -> tuple[str, ...]:
    """The cameras asked for, the primary first; () to read the default camera alone."""
    if cameras is None:
        return () if camera is None else (camera,)
    names = tuple(cameras)
    if not names or len(set(names)) < len(names) or camera not in (None, names[0]):
        raise ValueError(f"cameras must be distinct names, starting with camera={camera!r} if given; got {list(names)}")
    return names


def _check_views(views: dict[str, np.ndarray], refs: dict[str, EpisodeRef]) -> None:
    """Every camera's frames of an episode must have the primary's (first) count and size.

    Raises:
        DatasetError: naming the camera, the episode, the file and both shapes.
    """
    (primary, expected), *others = views.items()
    for name, frames in others:
        if frames.shape != expected.shape:
            ref = refs[name]
            raise DatasetError(
                f"{ref.video_path or ref.data_path}: camera {name!r} of episode {ref.index} has frames "
                f"{frames.shape} (count, H, W, 3) but camera {primary!r} has {expected.shape}"
            )
