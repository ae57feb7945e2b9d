"""Append episodes to a LeRobot v3.0 dataset, durably and resumably.

The life of an episode:

1. `LeRobotWriter.add` stages it in ``.staging/`` (`gymnast.data.staging`): from then on a crash
   cannot lose it.
2. `LeRobotWriter.flush` turns every staged episode into one new video file, one new data file and
   one new episode-metadata file (the next file index: a committed file is never rewritten),
   checks the video by decoding it, rewrites ``meta/tasks.parquet`` and ``meta/stats.json``, and
   last replaces ``meta/info.json``: that replacement is the commit. Then it unstages them.
3. A writer opened on a dataset whose last flush was interrupted restores the last commit: it
   deletes files that no committed episode refers to, rebuilds ``tasks.parquet`` and
   ``stats.json`` if they are not the ones ``info.json`` pinned (by SHA-256), unstages episodes
   that were committed, and keeps the others for the next flush.

Readers trust only ``info.json`` (``total_episodes``), so they see the last commit whatever state
the other files are in. One writer per dataset at a time.

Several cameras: each is its own video feature ``observation.images.<camera>``, with its own video
files (one per flush, like the data files), episode-metadata columns and stats; the first camera
is the primary, whose frames are `Episode.frames`, and the others come from `Episode.views`.

Legend: K episodes in a flush, L frames of an episode.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa

from gymnast.data.lerobot_format import (
    KEY_COLUMN,
    PSNR_COLUMN,
    aggregate_stats,
    episode_stats,
    flatten_stats,
    frame_columns,
    image_key,
    info_columns,
    stats_to_json,
    to_arrow,
    unflatten_stats,
)
from gymnast.data.lerobot_v3 import (
    CODEBASE_VERSION,
    DATA_PATH,
    DEFAULT_CHUNKS_SIZE,
    DEFAULT_DATA_FILE_SIZE_IN_MB,
    DEFAULT_VIDEO_FILE_SIZE_IN_MB,
    EPISODES_DIR,
    EPISODES_PATH,
    INFO_PATH,
    STATS_PATH,
    TASKS_PATH,
    VIDEO_PATH,
    build_features,
    load_info,
    read_episode_rows,
    read_tasks,
    tasks_table,
    video_columns,
)
from gymnast.data.schema import Episode
from gymnast.data.staging import StagingArea
from gymnast.utils.atomic import atomic_path, is_temporary, read_json, write_json, write_parquet
from gymnast.utils.video import DEFAULT_CODEC, VideoCodec, decode_video, encode_video, psnr, video_info

logger = logging.getLogger(__name__)

STAGING_DIR = ".staging"
MIN_PSNR_DB = 40.0
"""Below this the writer warns: decoded frames would no longer be faithful training targets."""


class LeRobotWriter:
    """Writes `Episode` objects to a LeRobot v3.0 dataset (created on the first flush).

    Args:
        root: dataset directory.
        fps: frames per second (Meta-World's control rate is 80).
        camera: camera name; frames go to the feature ``observation.images.<camera>``.
        cameras: every camera recorded, the primary (`Episode.frames`) first, the others read from
            `Episode.views`; when given it replaces `camera`.
        codec: how frames are compressed (see `gymnast.utils.video`).
        robot_type: ``robot_type`` in ``info.json``.
        chunks_size: files per chunk directory before the next chunk starts.

    Raises:
        ValueError: ``root`` holds a dataset with another fps, cameras, codec, robot type or chunk
            size, or one not written by gymnast (the message names the field and both values), or
            `cameras` is empty or names a camera twice.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        fps: int = 80,
        camera: str = "front",
        cameras: Sequence[str] | None = None,
        codec: VideoCodec = DEFAULT_CODEC,
        robot_type: str = "sawyer",
        chunks_size: int = DEFAULT_CHUNKS_SIZE,
    ) -> None:
        self.root = Path(root)
        self.cameras = tuple(cameras) if cameras is not None else (camera,)
        if not self.cameras or len(set(self.cameras)) < len(self.cameras):
            raise ValueError(f"cameras must be one or more distinct names, got {list(self.cameras)}")
        self.fps, self.camera, self.codec, self.robot_type = fps, self.cameras[0], codec, robot_type
        self.chunks_size = chunks_size
        self.image_key = image_key(self.camera)
        self.image_keys = tuple(image_key(name) for name in self.cameras)
        self._info: dict | None = None
        self._rows: list[dict] = []  # committed episode-metadata rows, without the stats columns
        if (self.root / INFO_PATH).exists():
            self._info = load_info(self.root)
            self._check_compatible(self._info)
            self._rows = [row for _, row in read_episode_rows(self.root, self._info)]
        self._recover()
        # The committed tasks and stats stay in memory, so a flush that failed after rewriting
        # their files can be retried without counting anything twice.
        self._tasks = read_tasks(self.root / TASKS_PATH) if self._info else {}
        self._stats = read_json(self.root / STATS_PATH) if self._info else {}
        self._staging = StagingArea(self.root / STAGING_DIR)
        committed = {row[KEY_COLUMN] for row in self._rows}
        for number in self._staging.numbers():
            if self._staging.info(number).key in committed:  # the crash came after the commit
                logger.info("%s: unstaging episode %d, already committed", self.root, number)
                self._staging.remove(number)
        self._shapes = self._committed_shapes()
        if self._shapes is None and len(self._staging):
            self._shapes = _episode_shapes(self._staging.load(self._staging.numbers()[0]), self._videos)

    @property
    def num_episodes(self) -> int:
        """Episodes committed to the dataset."""
        return len(self._rows)

    @property
    def num_staged(self) -> int:
        """Episodes added (durable) but not yet flushed into the dataset files."""
        return len(self._staging)

    def keys(self) -> frozenset[str]:
        """`EpisodeInfo.key` of every committed or staged episode: work a collector can skip."""
        return frozenset(row[KEY_COLUMN] for row in self._rows) | self._staging.keys()

    def add(self, episode: Episode) -> None:
        """Stage an episode; it is on disk (and survives a crash) when this returns.

        Raises:
            ValueError: the episode's key is already in the dataset, it has no step, its cameras
                (`Episode.views`, or none but the primary) are not the writer's, or a shape differs
                from the dataset's (the message names the feature and both shapes).
        """
        if not isinstance(episode, Episode):
            raise TypeError(f"add() takes an Episode, got {type(episode).__name__}")
        key = episode.info.key
        if episode.length < 1:
            raise ValueError(f"episode {key!r} has no step")
        if key in self.keys():
            raise ValueError(f"episode {key!r} is already in {self.root}")
        shapes = _episode_shapes(episode, self._videos)
        for name, shape in (self._shapes or shapes).items():
            if shapes[name] != shape:
                raise ValueError(f"{name}: the dataset has shape {shape}, episode {key!r} has {shapes[name]}")
        self._staging.add(episode)
        self._shapes = self._shapes or shapes

    def flush(self) -> int:
        """Commit every staged episode to the dataset files; returns how many were committed."""
        numbers = self._staging.numbers()
        if not numbers:
            return 0
        episodes = [self._staging.load(n) for n in numbers]
        info = copy.deepcopy(self._info) if self._info else self._new_info()
        tasks = dict(self._tasks)
        chunk, file = self._next_file()
        where = {"chunk_index": chunk, "file_index": file}
        offsets = [0, *itertools.accumulate(ep.length + 1 for ep in episodes)]  # K + 1 frame offsets
        videos = [self._videos(episode) for episode in episodes]
        streams, camera_psnr = {}, []
        for key in self.image_keys:
            worst, streams[key] = self._write_video(
                VIDEO_PATH.format(video_key=key, **where), [v[key] for v in videos], offsets
            )
            camera_psnr.append(worst)
        video_psnr = [min(values) for values in zip(*camera_psnr, strict=True)]  # each episode's worst camera

        first_episode, first_row = info["total_episodes"], info["total_frames"]
        columns, rows, stats = [], [], []
        for k, episode in enumerate(episodes):
            task_index = tasks.setdefault(episode.info.instruction, len(tasks))
            columns.append(
                frame_columns(episode, first_episode + k, first_row + offsets[k], task_index, self.fps)
            )
            stats.append(episode_stats(columns[-1], videos[k]))
            row = self._meta_row(first_episode + k, episode, first_row + offsets[k], offsets[k], chunk, file)
            rows.append(row | {PSNR_COLUMN: video_psnr[k]})
        data = {name: np.concatenate([c[name] for c in columns]) for name in columns[0]}
        write_parquet(self.root / DATA_PATH.format(**where), pa.table(to_arrow(data)))
        stats_columns = [flatten_stats(s) for s in stats]
        write_parquet(
            self.root / EPISODES_PATH.format(**where),
            pa.Table.from_pylist([row | s for row, s in zip(rows, stats_columns, strict=True)]),
        )

        info["features"] = info["features"] or build_features(self._shapes, self.fps, streams)
        info |= {
            "total_episodes": first_episode + len(episodes),
            "total_frames": first_row + offsets[-1],
            "total_tasks": len(tasks),
            "splits": {"train": f"0:{first_episode + len(episodes)}"},
        }
        info["gymnast"]["video_psnr_db"] = _psnr_summary([r[PSNR_COLUMN] for r in self._rows + rows])
        all_stats = stats_to_json(aggregate_stats([self._stats, *stats] if self._stats else stats))
        self._commit(info, tasks, all_stats)

        self._info, self._rows, self._tasks, self._stats = info, self._rows + rows, tasks, all_stats
        for number in numbers:
            self._staging.remove(number)
        worst = min(video_psnr)
        log = logger.warning if worst < MIN_PSNR_DB else logger.info
        log("%s: committed %d episodes, worst video frame %.1f dB PSNR", self.root, len(episodes), worst)
        return len(episodes)

    def __enter__(self) -> LeRobotWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        # On an error the staged episodes stay on disk for the next writer: nothing is lost.
        if exc_type is None:
            self.flush()

    def _videos(self, episode: Episode) -> dict[str, np.ndarray]:
        """Each camera feature's (L, H, W, 3) frames of the episode.

        Raises:
            ValueError: the episode's cameras are not the writer's (both named).
        """
        names = list(episode.views) or [self.camera]  # frames alone: the primary camera's
        if names != list(self.cameras):
            raise ValueError(f"episode {episode.info.key!r} has cameras {names} but {self.root} records "
                             f"{list(self.cameras)}")
        return {key: episode.views.get(name, episode.frames) for name, key in zip(self.cameras, self.image_keys)}

    def _write_video(self, rel: str, clips: list[np.ndarray], offsets: list[int]) -> tuple[list[float], dict]:
        """Encode one camera's frames of the episodes into one file, each episode starting on a key
        frame, and verify it.

        Returns:
            The worst-frame PSNR of each episode and the stream description for ``info.json``.
        """
        with atomic_path(self.root / rel) as tmp:
            frames = np.concatenate(clips)  # (sum of L, H, W, 3)
            encode_video(tmp, frames, self.fps, self.codec, keyframes=offsets[:-1])
            decoded = decode_video(tmp)  # before the rename: a file that fails here is never committed
            stream = video_info(tmp)
        spans = zip(clips, offsets[:-1], offsets[1:], strict=True)
        return [float(psnr(clip, decoded[a:b]).per_frame.min()) for clip, a, b in spans], stream

    def _meta_row(
        self, index: int, episode: Episode, first_row: int, offset: int, chunk: int, file: int
    ) -> dict:
        """LeRobot's episode-metadata columns (``offset``: first frame in the videos) and ours."""
        n_rows = episode.length + 1
        row = {
            "episode_index": index,
            "tasks": [episode.info.instruction],
            "length": n_rows,
            "data/chunk_index": chunk,
            "data/file_index": file,
            "dataset_from_index": first_row,
            "dataset_to_index": first_row + n_rows,
        }
        span = (chunk, file, offset / self.fps, (offset + n_rows) / self.fps)
        for key in self.image_keys:  # every camera's videos are written together, so at one offset
            row |= dict(zip(video_columns(key), span, strict=True))  # videos/<key>/chunk_index, ...
        row |= {"meta/episodes/chunk_index": chunk, "meta/episodes/file_index": file}
        return row | info_columns(episode.info)

    def _commit(self, info: dict, tasks: dict[str, int], stats: dict) -> None:
        """Write tasks and stats, pin their bytes in info.json, then replace info.json."""
        write_parquet(self.root / TASKS_PATH, tasks_table(tasks))
        write_json(self.root / STATS_PATH, stats)
        info["gymnast"]["meta_sha256"] = {rel: _sha256(self.root / rel) for rel in (TASKS_PATH, STATS_PATH)}
        write_json(self.root / INFO_PATH, info)

    def _new_info(self) -> dict:
        return {
            "codebase_version": CODEBASE_VERSION,
            "robot_type": self.robot_type,
            "total_episodes": 0,
            "total_frames": 0,
            "total_tasks": 0,
            "chunks_size": self.chunks_size,
            "data_files_size_in_mb": DEFAULT_DATA_FILE_SIZE_IN_MB,
            "video_files_size_in_mb": DEFAULT_VIDEO_FILE_SIZE_IN_MB,
            "fps": self.fps,
            "splits": {},
            "data_path": DATA_PATH,
            "video_path": VIDEO_PATH,
            "features": {},
            "gymnast": {"codec": _codec_json(self.codec)},
        }

    def _check_compatible(self, info: dict) -> None:
        path = self.root / INFO_PATH
        if not isinstance(info.get("gymnast"), dict) or info.get("codebase_version") != CODEBASE_VERSION:
            raise ValueError(
                f"{path}: not a v3.0 dataset written by gymnast; appending to it is not supported"
            )
        features = info.get("features", {})
        cameras = [
            k.removeprefix("observation.images.") for k, f in features.items() if f.get("dtype") == "video"
        ]
        settings = {
            "fps": (info.get("fps"), self.fps),
            "camera": (cameras, list(self.cameras)),
            "robot_type": (info.get("robot_type"), self.robot_type),
            "chunks_size": (info.get("chunks_size"), self.chunks_size),
            "codec": (info["gymnast"].get("codec"), _codec_json(self.codec)),
        }
        for field, (existing, requested) in settings.items():
            if existing != requested:
                raise ValueError(
                    f"{path}: {field} is {existing!r} in the dataset but the writer was given {requested!r}"
                )

    def _committed_shapes(self) -> dict[str, tuple[int, ...]] | None:
        features = (self._info or {}).get("features")
        if not features:
            return None
        env = features.get("observation.environment_state", {"shape": [0]})
        return {
            "observation.state": tuple(features["observation.state"]["shape"]),
            "observation.environment_state": tuple(env["shape"]),
            "action": tuple(features["action"]["shape"]),
        } | {key: tuple(features[key]["shape"]) for key in self.image_keys}

    def _next_file(self) -> tuple[int, int]:
        if not self._rows:
            return 0, 0
        chunk, file = max((r["data/chunk_index"], r["data/file_index"]) for r in self._rows)
        return (chunk, file + 1) if file + 1 < self.chunks_size else (chunk + 1, 0)

    def _recover(self) -> None:
        """Bring the files back to the last commit (see the module docstring)."""
        for path in self.root.rglob(".*"):
            if path.is_file() and is_temporary(path):
                logger.warning("removing %s, left by an interrupted write", path)
                path.unlink()
        referenced = set()
        for row in self._rows:
            data = {"chunk_index": row["data/chunk_index"], "file_index": row["data/file_index"]}
            meta = {
                "chunk_index": row["meta/episodes/chunk_index"],
                "file_index": row["meta/episodes/file_index"],
            }
            referenced |= {DATA_PATH.format(**data), EPISODES_PATH.format(**meta)}
            referenced |= {VIDEO_PATH.format(video_key=key, **data) for key in self.image_keys}
        files = "chunk-*/file-*"
        patterns = (
            f"data/{files}.parquet",
            *(f"videos/{key}/{files}.mp4" for key in self.image_keys),
            f"{EPISODES_DIR}/{files}.parquet",
        )
        for pattern in patterns:
            for path in self.root.glob(pattern):
                if path.relative_to(self.root).as_posix() not in referenced:
                    logger.warning("removing %s: no committed episode refers to it (interrupted flush)", path)
                    path.unlink()
        if self._info is None:
            for rel in (TASKS_PATH, STATS_PATH):
                (self.root / rel).unlink(missing_ok=True)
            return
        pinned = self._info["gymnast"].get("meta_sha256", {})
        if all(_sha256(self.root / rel) == digest for rel, digest in pinned.items()):
            return
        logger.warning("%s: rebuilding tasks and stats of the last commit (interrupted flush)", self.root)
        tasks = read_tasks(self.root / TASKS_PATH)
        tasks = {task: i for task, i in tasks.items() if i < self._info["total_tasks"]}  # indices only grow
        rows = read_episode_rows(self.root, self._info, keep=lambda name: name.startswith("stats/"))
        stats = aggregate_stats([unflatten_stats(row) for _, row in rows])
        self._commit(self._info, tasks, stats_to_json(stats))


def _episode_shapes(episode: Episode, videos: Callable[[Episode], dict[str, np.ndarray]]) -> dict[str, tuple[int, ...]]:
    """Every feature's shape in the episode; `videos` gives each camera feature's frames."""
    return {
        "observation.state": episode.states.shape[1:],
        "observation.environment_state": episode.env_states.shape[1:],
        "action": episode.actions.shape[1:],
    } | {key: frames.shape[1:] for key, frames in videos(episode).items()}


def _codec_json(codec: VideoCodec) -> dict:
    return {"codec": codec.codec, "pix_fmt": codec.pix_fmt, "options": dict(codec.options)}


def _psnr_summary(values: list[float]) -> dict:
    """Worst frame of the dataset and mean over episodes of their worst frame; null = bit-exact."""
    finite = [v for v in values if math.isfinite(v)]
    return {"min": min(finite) if finite else None, "mean": sum(finite) / len(finite) if finite else None}


def _sha256(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
