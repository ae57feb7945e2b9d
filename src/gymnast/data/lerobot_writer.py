"""Append episodes to a LeRobot v3.0 dataset, durably and resumably.

The life of an episode:

1. `LeRobotWriter.add` stages it as ``.staging/<n>.npz`` (written atomically): from then on a crash
   cannot lose it.
2. `LeRobotWriter.flush` turns every staged episode into one new data file, one new video file and one
   new episode-metadata file (the next file index; a committed file is never rewritten), checks the
   video by decoding it, rewrites ``meta/tasks.parquet`` and ``meta/stats.json``, and last replaces
   ``meta/info.json``: that replacement is the commit. Then it deletes the staged files.
3. A writer opened on a dataset whose last flush was interrupted restores the last commit: it
   deletes files that no committed episode references, rebuilds ``tasks.parquet`` and
   ``stats.json`` if they are not the ones ``info.json`` pinned (by SHA-256), drops staged episodes
   that were committed, and keeps the others for the next flush.

Readers only trust ``info.json`` (``total_episodes``), so they see the last commit whatever state
the other files are in. One writer per dataset at a time.
"""

from __future__ import annotations

import copy
import hashlib
import io
import itertools
import json
import logging
import math
from pathlib import Path

import numpy as np
import pyarrow as pa

from gymnast.data.lerobot_format import (
    KEY_COLUMN,
    PSNR_COLUMN,
    aggregate_stats,
    episode_stats,
    frame_columns,
    image_key,
    info_columns,
    stats_to_json,
    to_arrow,
)
from gymnast.data.lerobot_v3 import (
    CODEBASE_VERSION,
    DATA_PATH,
    DEFAULT_CHUNKS_SIZE,
    DEFAULT_DATA_FILE_SIZE_IN_MB,
    DEFAULT_VIDEO_FILE_SIZE_IN_MB,
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
)
from gymnast.data.schema import Episode, EpisodeInfo
from gymnast.utils.atomic import atomic_path, is_temporary, write_bytes, write_json, write_parquet
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
        codec: how frames are compressed (see `gymnast.utils.video`).
        robot_type: ``robot_type`` in ``info.json``.
        chunks_size: files per chunk directory before the next chunk starts.

    Raises:
        ValueError: ``root`` holds a dataset with another fps, camera, codec, robot type or chunk
            size, or one not written by gymnast; the message names the field and both values.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        fps: int = 80,
        camera: str = "front",
        codec: VideoCodec = DEFAULT_CODEC,
        robot_type: str = "sawyer",
        chunks_size: int = DEFAULT_CHUNKS_SIZE,
    ) -> None:
        self.root = Path(root)
        self.fps, self.camera, self.codec, self.robot_type = fps, camera, codec, robot_type
        self.chunks_size = chunks_size
        self.image_key = image_key(camera)
        self._staging = self.root / STAGING_DIR
        self._info: dict | None = load_info(self.root) if (self.root / INFO_PATH).exists() else None
        if self._info is not None:
            self._check_compatible(self._info)
        self._rows = [row for _, row in read_episode_rows(self.root, self._info)] if self._info else []
        self._recover()
        # The committed task table and stats, kept in memory so that a flush that failed halfway
        # (after rewriting these files) can be retried without counting anything twice.
        self._tasks = read_tasks(self.root / TASKS_PATH) if self._info else {}
        self._stats = json.loads((self.root / STATS_PATH).read_text()) if self._info else {}
        self._staged: dict[int, str] = {}  # staging sequence number -> episode key
        self._next_seq = 0
        self._shapes = self._committed_shapes()
        self._scan_staging()

    @property
    def num_episodes(self) -> int:
        """Episodes committed to the dataset."""
        return len(self._rows)

    @property
    def num_staged(self) -> int:
        """Episodes added (durable) but not yet flushed into the dataset files."""
        return len(self._staged)

    def keys(self) -> frozenset[str]:
        """`EpisodeInfo.key` of every committed or staged episode: work a collector can skip."""
        return frozenset(row[KEY_COLUMN] for row in self._rows) | frozenset(self._staged.values())

    def add(self, episode: Episode) -> None:
        """Stage an episode; it is on disk (and survives a crash) when this returns.

        Raises:
            ValueError: the episode's key is already in the dataset, it has no step, or a shape
                differs from the dataset's (the message names the feature and both shapes).
        """
        if not isinstance(episode, Episode):
            raise TypeError(f"add() takes an Episode, got {type(episode).__name__}")
        if episode.length < 1:
            raise ValueError(f"episode {episode.info.key!r} has no step")
        key = episode.info.key
        if key in self.keys():
            raise ValueError(f"episode {key!r} is already in {self.root}")
        shapes = _episode_shapes(episode, self.image_key)
        for name, shape in (self._shapes or {}).items():
            if shapes[name] != shape:
                raise ValueError(f"{name}: the dataset has shape {shape}, episode {key!r} has {shapes[name]}")
        buffer = io.BytesIO()
        np.savez(
            buffer,
            frames=episode.frames,
            states=episode.states.astype(np.float32),
            env_states=episode.env_states.astype(np.float32),
            actions=episode.actions.astype(np.float32),
            rewards=episode.rewards.astype(np.float32),
            successes=episode.successes.astype(bool),
            info=np.array(json.dumps(episode.info.to_dict())),
        )
        write_bytes(self._staging / f"{self._next_seq:08d}.npz", buffer.getvalue())
        self._staged[self._next_seq] = key
        self._next_seq += 1
        self._shapes = self._shapes or shapes

    def flush(self) -> int:
        """Commit every staged episode to the dataset files; returns how many were committed."""
        if not self._staged:
            return 0
        seqs = sorted(self._staged)
        episodes = [self._load_staged(seq) for seq in seqs]
        info = copy.deepcopy(self._info) if self._info else self._new_info()
        tasks = dict(self._tasks)
        chunk, file = self._next_file()
        where = {"chunk_index": chunk, "file_index": file}
        data_path, meta_path = DATA_PATH.format(**where), EPISODES_PATH.format(**where)
        video_path = VIDEO_PATH.format(video_key=self.image_key, **where)

        starts = [0, *itertools.accumulate(ep.length + 1 for ep in episodes)]  # K + 1 video frame offsets
        with atomic_path(self.root / video_path) as tmp:
            encode_video(tmp, np.concatenate([ep.frames for ep in episodes]), self.fps, self.codec, starts[:-1])
            decoded = decode_video(tmp)  # verify before the file can be committed
            stream = video_info(tmp)
        video_psnr = [float(psnr(ep.frames, decoded[a:b]).per_frame.min()) for ep, a, b in zip(episodes, starts, starts[1:])]

        columns, rows, ep_stats = [], [], []
        first_episode, first_index = info["total_episodes"], info["total_frames"]
        for k, episode in enumerate(episodes):
            task_index = tasks.setdefault(episode.info.instruction, len(tasks))
            cols = frame_columns(episode, first_episode + k, first_index + starts[k], task_index, self.fps)
            stats = episode_stats(cols, self.image_key, episode.frames)
            columns.append(cols)
            ep_stats.append(stats)
            rows.append(self._meta_row(first_episode + k, episode, first_index + starts[k], starts[k], chunk, file))
            rows[-1][PSNR_COLUMN] = video_psnr[k]
            rows[-1] |= {f"stats/{name}/{stat}": v for name, s in stats_to_json(stats).items() for stat, v in s.items()}
        data = {name: np.concatenate([c[name] for c in columns]) for name in columns[0]}
        write_parquet(self.root / data_path, pa.table(to_arrow(data)))
        write_parquet(self.root / meta_path, pa.Table.from_pylist(rows))

        info["features"] = info["features"] or build_features(self._shapes, self.fps, self.image_key, stream)
        info |= {
            "total_episodes": first_episode + len(episodes),
            "total_frames": first_index + starts[-1],
            "total_tasks": len(tasks),
            "splits": {"train": f"0:{first_episode + len(episodes)}"},
        }
        new_rows = [{k: v for k, v in row.items() if not k.startswith("stats/")} for row in rows]
        info["gymnast"]["video_psnr_db"] = _psnr_summary([r[PSNR_COLUMN] for r in self._rows + new_rows])
        stats = stats_to_json(aggregate_stats([self._stats, *ep_stats] if self._stats else ep_stats))
        self._write_meta(info, tasks, stats)  # commits

        self._info, self._rows, self._tasks, self._stats = info, self._rows + new_rows, tasks, stats
        for seq in seqs:
            (self._staging / f"{seq:08d}.npz").unlink()
            del self._staged[seq]
        worst = min(video_psnr)
        log = logger.warning if worst < MIN_PSNR_DB else logger.info
        log("%s: committed %d episodes to %s (video PSNR >= %.1f dB)", self.root, len(episodes), data_path, worst)
        return len(episodes)

    def __enter__(self) -> LeRobotWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        # On an error the staged episodes stay on disk for the next writer: nothing is lost.
        if exc_type is None:
            self.flush()

    def _meta_row(self, index: int, episode: Episode, first: int, offset: int, chunk: int, file: int) -> dict:
        n_rows, video = episode.length + 1, f"videos/{self.image_key}/"
        return {
            "episode_index": index,
            "tasks": [episode.info.instruction],
            "length": n_rows,
            "data/chunk_index": chunk,
            "data/file_index": file,
            "dataset_from_index": first,
            "dataset_to_index": first + n_rows,
            video + "chunk_index": chunk,
            video + "file_index": file,
            video + "from_timestamp": offset / self.fps,
            video + "to_timestamp": (offset + n_rows) / self.fps,
            "meta/episodes/chunk_index": chunk,
            "meta/episodes/file_index": file,
        } | info_columns(episode.info)

    def _write_meta(self, info: dict, tasks: dict[str, int], stats: dict) -> None:
        """Write tasks and stats, pin their bytes in info.json, then replace info.json (the commit)."""
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
            raise ValueError(f"{path}: not a v3.0 dataset written by gymnast; appending to it is not supported")
        cameras = [k.removeprefix("observation.images.") for k, f in info["features"].items() if f.get("dtype") == "video"]
        wanted = {
            "fps": (info.get("fps"), self.fps),
            "camera": (cameras, [self.camera]),
            "robot_type": (info.get("robot_type"), self.robot_type),
            "chunks_size": (info.get("chunks_size"), self.chunks_size),
            "codec": (info["gymnast"].get("codec"), _codec_json(self.codec)),
        }
        for field, (existing, requested) in wanted.items():
            if existing != requested:
                raise ValueError(f"{path}: {field} is {existing!r} in the dataset but the writer was given {requested!r}")

    def _committed_shapes(self) -> dict[str, tuple[int, ...]] | None:
        features = (self._info or {}).get("features")
        if not features:
            return None
        env = features.get("observation.environment_state", {"shape": [0]})
        return {
            "observation.state": tuple(features["observation.state"]["shape"]),
            "observation.environment_state": tuple(env["shape"]),
            "action": tuple(features["action"]["shape"]),
            self.image_key: tuple(features[self.image_key]["shape"]),
        }

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
            where = {"chunk_index": row["data/chunk_index"], "file_index": row["data/file_index"]}
            referenced |= {DATA_PATH.format(**where), VIDEO_PATH.format(video_key=self.image_key, **where)}
            referenced.add(EPISODES_PATH.format(chunk_index=row["meta/episodes/chunk_index"], file_index=row["meta/episodes/file_index"]))
        patterns = ("data/chunk-*/file-*.parquet", f"videos/{self.image_key}/chunk-*/file-*.mp4", "meta/episodes/chunk-*/file-*.parquet")
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
        tasks = {t: i for t, i in read_tasks(self.root / TASKS_PATH).items() if i < self._info["total_tasks"]}
        stats_rows = read_episode_rows(self.root, self._info, keep=lambda n: n.startswith("stats/") or n == "episode_index")
        stats = aggregate_stats([_unflatten_stats(row) for _, row in stats_rows])
        self._write_meta(self._info, tasks, stats_to_json(stats))

    def _scan_staging(self) -> None:
        committed = {row[KEY_COLUMN] for row in self._rows}
        for path in sorted(self._staging.glob("*.npz")):
            seq = int(path.stem)
            self._next_seq = max(self._next_seq, seq + 1)
            with np.load(path, allow_pickle=False) as staged:
                info = EpisodeInfo(**json.loads(str(staged["info"])))
                if self._shapes is None:
                    self._shapes = _episode_shapes(self._load_staged(seq), self.image_key)
            if info.key in committed:
                logger.info("dropping staged %s: episode %r is already committed", path, info.key)
                path.unlink()
            else:
                self._staged[seq] = info.key

    def _load_staged(self, seq: int) -> Episode:
        with np.load(self._staging / f"{seq:08d}.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in ("frames", "states", "env_states", "actions", "rewards", "successes")}
            return Episode(**arrays, info=EpisodeInfo(**json.loads(str(z["info"]))))


def _episode_shapes(episode: Episode, image_key: str) -> dict[str, tuple[int, ...]]:
    return {
        "observation.state": episode.states.shape[1:],
        "observation.environment_state": episode.env_states.shape[1:],
        "action": episode.actions.shape[1:],
        image_key: episode.frames.shape[1:],
    }


def _codec_json(codec: VideoCodec) -> dict:
    return {"codec": codec.codec, "pix_fmt": codec.pix_fmt, "options": dict(codec.options)}


def _psnr_summary(values: list[float]) -> dict:
    """Worst frame of the dataset and mean over episodes of their worst frame; null = bit-exact."""
    finite = [v for v in values if math.isfinite(v)]
    return {"min": min(finite) if finite else None, "mean": sum(finite) / len(finite) if finite else None}


def _sha256(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def _unflatten_stats(row: dict) -> dict:
    """``{"stats/<feature>/<stat>": value}`` columns -> ``{feature: {stat: value}}``."""
    stats: dict = {}
    for name, value in row.items():
        if name.startswith("stats/"):
            feature, stat = name.removeprefix("stats/").rsplit("/", 1)
            stats.setdefault(feature, {})[stat] = value
    return stats
