"""The videos a judge learns from and is measured on: real episodes, their re-imaginings by a world
model under the real actions, and the cases cut from them.

Legend: T steps, H/W image size.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import Episode
from gymnast.reward.judges.progress import progress_targets
from gymnast.world_model.base import load_world_model, placed
from gymnast.world_model.data import split_episodes, usable_episodes
from gymnast.world_model.reimagine import reimagine, require_same_cameras

NEAR_MISS_STEPS = 10  # a held-out negative: a successful episode cut this many steps before its success


@dataclass(frozen=True)
class Video:
    """One episode's video (real or imagined) with its success per frame.

    Attributes:
        frames: (T+1, H, W, 3) uint8.
        success: (T+1,) bool frame t counts once the episode has succeeded by then.
        shows: (T+1,) bool the task is done in frame t (Meta-World's per-step flag; an object
            knocked off its goal again undoes it); frame 0 never.
        instruction: the task in words.
        imagined: re-imagined by a world model under the episode's real actions.
        progress: (T+1,) float32 the dense reward that led to frame t, scaled to [0, 1] (0 at the
            start frame): the progress judge's targets.
    """

    frames: torch.Tensor
    success: torch.Tensor
    shows: torch.Tensor
    instruction: str
    imagined: bool
    progress: torch.Tensor


def real_video(episode: Episode) -> Video:
    """A recorded episode as a judge sees it: every camera read, side by side, with its successes."""
    frames = torch.from_numpy(episode.observed_frames)
    shows = torch.cat([torch.zeros(1, dtype=torch.bool), torch.from_numpy(episode.successes).bool()])
    return Video(frames, shows.cummax(0).values, shows, episode.info.instruction, imagined=False,
                 progress=progress_targets(episode.rewards))


def load_videos(dataset: EpisodeDataset, indices: list[int], wm: Path | None, progress: bool,
                device: torch.device | None = None) -> list[Video]:
    """Real videos of the episodes, plus their re-imaginings under the real actions with a world
    model (on `device`, the host by default)."""
    videos, episodes = [], []
    for i in tqdm(indices, desc="loading episodes", disable=not progress):
        episode = dataset.load(i)
        videos.append(real_video(episode))
        episodes.append(torch.from_numpy(episode.actions).float())
    if wm is None:
        return videos
    model = placed(load_world_model(wm), device or torch.device("cpu"))
    require_same_cameras(dataset, model, wm, "re-imagine with a world model of the judge's cameras "
                         "(`gymnast train-wm --cameras`), or train the judge without --wm")
    imagined = reimagine(model, [video.frames[0] for video in videos], episodes, progress)
    return [video for real, frames in zip(videos, imagined)
            for video in (real, dataclasses.replace(real, frames=frames, imagined=True))]


def heldout_videos(dataset: EpisodeDataset, fraction: float, wm: Path | None = None,
                   device: torch.device | None = None) -> list[Video]:
    """The videos of the held-out scenes' episodes (and their re-imaginings with a world model on `device`);
    at `fraction` 1 every episode's, for a dataset of scenes recorded apart from everything trained
    (except those on evaluation seeds, as everywhere)."""
    chosen = usable_episodes(dataset.episodes) if fraction == 1 else split_episodes(dataset.episodes, fraction)[1]
    return load_videos(dataset, chosen, wm, progress=False, device=device)


def judge_cases(videos: list[Video]) -> list[tuple[torch.Tensor, str, bool, bool, bool]]:
    """What a judge is measured on: (frames, instruction, label, whole episode?, imagined?) for every
    whole video, and for successful ones, cuts halfway to their success and `NEAR_MISS_STEPS` short."""
    cases = []
    for video in videos:
        cases.append((video.frames, video.instruction, bool(video.success[-1]), True, video.imagined))
        if video.success[-1]:
            first = int(video.success.float().argmax())  # the first frame showing success
            for cut in sorted({first // 2, first - NEAR_MISS_STEPS}):  # halfway there; a few steps short
                if cut >= 2:
                    cases.append((video.frames[:cut], video.instruction, False, False, video.imagined))
    return cases
