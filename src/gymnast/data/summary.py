"""What a dataset holds, for people: the summary `gymnast inspect` prints and a contact sheet of episodes;
for a dataset whose features are named otherwise, what could be its actions, states and cameras."""

from __future__ import annotations

import json
from pathlib import Path

from gymnast.data.collect import success_table
from gymnast.data.features import candidates, describe, flag, has_feature, suggestion
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.lerobot_format import FeatureKeys
from gymnast.data.lerobot_v3 import load_info
from gymnast.utils.images import contact_sheet, save_png

_DEFAULTS = {"action": FeatureKeys().action_key, "state": FeatureKeys().state_key}


def describe_dataset(dataset: EpisodeDataset) -> str:
    """Format, episodes, steps, frame rate, camera, image size and action width; the features read as
    actions and states; every camera of the dataset; the codec's decoded-vs-raw error when the
    recorder measured it; success by task and behaviour."""
    lines = [f"{dataset.root}: LeRobot {dataset.info['codebase_version']}, {len(dataset.episodes)} episodes, "
             f"{sum(dataset.lengths)} steps, {dataset.fps} fps, images {dataset.image_shape} from camera "
             f"{dataset.camera_key!r}, {dataset.action_dim}-D actions"]
    features, keys = dataset.info["features"], dataset.keys
    states = (describe(features, keys.state_key) if keys.state_key in features
              else f"none (no {keys.state_key!r}" + suggestion("state", features, taken=(keys.action_key,)) + ")")
    lines.append(f"actions: {describe(features, keys.action_key)}; states: {states}")
    lines.append("cameras: " + ", ".join(f"{name} {features[key].get('shape')} {features[key].get('dtype')}"
                                         for name, key in dataset.available_cameras.items()))
    recorded = dataset.info.get("gymnast", {})
    if "video_psnr_db" in recorded:
        lines.append(f"video: {json.dumps(recorded['codec'])}, decoded-vs-raw PSNR "
                     f"min {recorded['video_psnr_db']['min']:.1f} dB, mean {recorded['video_psnr_db']['mean']:.1f} dB")
    lines.append(format_success_table(success_table(dataset.episodes)))
    lines += [f"assumed: {deviation.found}; {deviation.decision}" for deviation in dataset.deviations]
    return "\n".join(lines)


def write_episode_sheet(dataset: EpisodeDataset, path: Path, episodes: int = 10) -> Path:
    """A PNG of the first, middle and last frame of the first `episodes` episodes, captioned."""
    frames, labels = [], []
    for i in range(min(episodes, len(dataset.episodes))):
        episode = dataset.load(i)
        for t in (0, episode.length // 2, episode.length):
            frames.append(episode.frames[t])
            labels.append(f"{i} {dataset.episodes[i].task[:14]} t={t}")
    return save_png(contact_sheet(frames, labels, columns=6), path)


def format_success_table(table: dict) -> str:
    """`success_table` as aligned text, tasks in rows and behaviours in columns: 'successes/episodes'."""
    behaviours = sorted({b for row in table.values() for b in row})
    width = max([len(t) for t in table] + [4])
    lines = [f"{'task':<{width}}  " + "  ".join(f"{b:>17}" for b in behaviours)]
    for task, row in sorted(table.items()):
        cells = [f"{row[b][0]:>3}/{row[b][1]:<3} ({row[b][0] / row[b][1]:>4.0%})" if b in row else f"{'-':>17}"
                 for b in behaviours]
        lines.append(f"{task:<{width}}  " + "  ".join(f"{c:>17}" for c in cells))
    return "\n".join(lines)


def describe_candidates(root: Path, keys: FeatureKeys, camera: str | None = None) -> str:
    """What could be the actions, the states and the cameras of the dataset at `root`, with shapes,
    and the flags that read the likeliest ones: what `gymnast inspect` prints when `keys` or
    `camera` name a feature the dataset lacks."""
    info = load_info(root)
    features = info.get("features", {})
    lines = [f"{root}: LeRobot {info.get('codebase_version')}; features that could be what gymnast reads:"]
    flags, taken = [], {keys.action_key}  # one feature cannot be both the actions and the states
    for role, key in (("action", keys.action_key), ("state", keys.state_key), ("camera", camera)):
        found = candidates(features, role)
        missing = key is not None and not has_feature(features, role, key)
        kind = "image or video features" if role == "camera" else "float vectors"
        lines.append(f"{role} ({kind}{f'; {key!r} is missing' if missing else ''}): "
                     + (", ".join(describe(features, k) for k in found) or "none"))
        if missing:
            key = next((k for k in found if k not in taken), None)
        if key is not None and key != _DEFAULTS.get(role):  # the flags read every feature, not only the missing
            flags.append(flag(role, key))
            taken.add(key)
    lines.append(f"pass: {' '.join(flags)}" if flags else "no feature could stand in for the missing ones")
    return "\n".join(lines)
