"""`gymnast inspect --check`: every way a dataset departs from the LeRobot specification, and the
decision each leads to.

The readers record what they assume as they read (`gymnast.data.deviations`); the check reads the
whole dataset the way training does (its metadata, every episode's rows and frames, the action
statistics) and adds what only a full read shows: meta files and ``info.json`` fields missing,
codecs other than H.264 or other than ``info.json`` says, cameras whose picture barely changes,
actions in raw units. A deviation that keeps training from proceeding is *blocking*: its
decision says what would fix it.

    report = check_dataset(Path("data/theirs"))
    print(format_check(Path("data/theirs"), report)); exit(1 if report.blocking else 0)
"""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np

from gymnast.data.deviations import Deviations
from gymnast.data.features import candidates, camera_features, describe
from gymnast.data.lerobot import SUPPORTED_VERSIONS, EpisodeDataset
from gymnast.data.lerobot_format import DatasetError, FeatureKeys
from gymnast.data.lerobot_v3 import INFO_PATH, STATS_PATH, load_info

_STATIC_LEVEL = 0.5
"""Mean absolute change between consecutive frames (of 255) below which a camera shows nothing moving."""
_RAW_UNITS = 100.0
"""Actions beyond this magnitude are in a robot's own units (servo ticks, degrees), not normalised ones."""
_META_FILES = {
    "v2.0": {"meta/tasks.jsonl": "tasks come from the episode list"},
    "v2.1": {"meta/tasks.jsonl": "tasks come from the episode list",
             "meta/episodes_stats.jsonl": "not needed: statistics are computed from the data files"},
    "v3.0": {"meta/tasks.parquet": "not needed: tasks come from meta/episodes"},
}
_INFO_FIELDS = ("robot_type", "total_episodes", "total_frames", "total_tasks", "splits")


def check_dataset(root: Path, camera: str | None = None, keys: FeatureKeys = FeatureKeys()) -> Deviations:
    """Read the dataset at `root` as training would and list every deviation found.

    Never raises for the dataset's content: what cannot be read is a blocking deviation naming the
    file, the field and the fix.
    """
    notes = Deviations()
    try:
        info = load_info(root)
    except DatasetError as e:
        notes.add(root / INFO_PATH, "info.json", str(e), "nothing can be read: give the dataset a meta/info.json",
                  blocking=True)
        return notes
    version = info.get("codebase_version")
    for field in _INFO_FIELDS:
        if field not in info:
            notes.add(root / INFO_PATH, field, f"{field!r} is missing", "not needed: counted from the files")
    for name, decision in _META_FILES.get(version if version in SUPPORTED_VERSIONS else "", {}).items():
        if not (root / name).is_file():
            notes.add(root / name, name, f"{name} is missing", decision)
    if not (root / STATS_PATH).is_file():
        notes.add(root / STATS_PATH, STATS_PATH, f"{STATS_PATH} is missing",
                  "action statistics (the normalisation) are computed from the data files")
    try:
        dataset = EpisodeDataset(root, camera, keys=keys)
    except DatasetError as e:
        notes.add(root, "dataset", str(e), "training cannot start", blocking=True)
        return notes
    _check_features(dataset, notes)
    _check_episodes(dataset, notes)
    _check_codecs(dataset, notes)
    notes.merge(dataset.deviations)
    return notes


def format_check(root: Path, notes: Deviations) -> str:
    """The check for people: a verdict, then one line per deviation with its decision."""
    verdict = "training cannot proceed" if notes.blocking else "training can proceed"
    lines = [f"{root}: {len(notes)} deviation{'s' * (len(notes) != 1)} from the LeRobot specification; {verdict}"]
    lines += [f"  {'refused' if d.blocking else 'assumed'}: {d}" for d in notes]
    return "\n".join(lines)


def _check_features(dataset: EpisodeDataset, notes: Deviations) -> None:
    features, info_path = dataset.info["features"], dataset.root / INFO_PATH
    if dataset.keys.state_key not in features:
        found = [key for key in candidates(features, "state") if key != dataset.keys.action_key]
        hint = f"; could be {describe(features, found[0])}: pass --state-key {found[0]}" if found else ""
        notes.add(info_path, dataset.keys.state_key, f"no {dataset.keys.state_key!r} feature{hint}",
                  "states are empty (only train-state needs them)")
    shapes = {key: features[key].get("shape") for key in camera_features(features)}
    if len({str(shape) for shape in shapes.values() if isinstance(shape, list)}) > 1:
        notes.add(info_path, "features", f"cameras of different sizes: {shapes}",
                  f"each is read alone (camera {dataset.camera_key!r} by default; --camera picks another)")


def _check_episodes(dataset: EpisodeDataset, notes: Deviations) -> None:
    """Every episode read as training reads it; the actions' range and each camera's motion."""
    try:
        stats = dataset.action_stats
    except DatasetError as e:
        notes.add(dataset.root, dataset.keys.action_key, str(e), "training cannot start", blocking=True)
        return
    peak = max(max(map(abs, stats.min)), max(map(abs, stats.max)))
    if peak > _RAW_UNITS:
        notes.add(dataset.root / STATS_PATH, dataset.keys.action_key, f"actions reach {peak:.5g} (raw units, e.g. servo "
                  "ticks)", "normalised per dimension by the dataset's min and max")
    for i in range(len(dataset)):
        try:
            episode = dataset.load(i)
        except DatasetError as e:
            notes.add(dataset.root, "episode", str(e), "training cannot read this episode: fix or remove it",
                      blocking=True)
            continue
        for name, frames in (episode.views or {dataset.camera_key: episode.frames}).items():
            change = np.abs(np.diff(frames.astype(np.int16), axis=0)).mean() if len(frames) > 1 else 0.0
            if change < _STATIC_LEVEL:
                notes.add(dataset.root, f"camera {name}", f"episode {i}'s frames barely change (mean {change:.2f}/255 "
                          "between frames)", "read as they are: a world model learns little from a still picture; "
                          "--camera picks another view")


def _check_codecs(dataset: EpisodeDataset, notes: Deviations) -> None:
    """The codec of each video camera's first file against ``info.json``'s."""
    features = dataset.info["features"]
    for key in camera_features(features):
        if features[key].get("dtype") != "video":
            continue
        try:
            path = next((path for path in dataset.video_files(key) if path.is_file()), None)
        except DatasetError:
            continue  # a camera not read; opening the dataset said what it lacks where it mattered
        if path is None:
            continue
        try:
            with av.open(str(path)) as container:
                context = container.streams.video[0].codec_context
                codec, pix_fmt = context.name, context.pix_fmt or ""
        except (OSError, IndexError, AttributeError, av.error.FFmpegError):
            continue  # no stream, or none described: reading the episodes names the unreadable file
        described = next((features[key][k] for k in ("info", "video_info") if isinstance(features[key].get(k), dict)), {})
        declared = described.get("video.codec")
        if declared is not None and str(declared).lower() not in (codec, {"hevc": "h265"}.get(codec), {"h264": "avc1"}.get(codec)):
            notes.add(path, f"features.{key}.info.video.codec", f"info.json says {declared!r}, the file is {codec!r}",
                      "the file's codec is decoded")
        if pix_fmt.startswith("gray"):
            notes.add(path, key, f"videos are grayscale ({pix_fmt})", "read as RGB, grey repeated to 3 channels")
        if codec != "h264":
            notes.add(path, key, f"videos are {codec}, not H.264", "decoded by FFmpeg (PyAV) like H.264")
