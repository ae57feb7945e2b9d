"""Recorded episodes re-imagined by a world model under their own actions, from their first frame.

What a judge learns imagined video from, and what a policy learns imagined sight from: the same
actions, the world model's drawing of what they do instead of the camera's.

Legend: T steps, H/W image size, A action dimensions.
"""

from __future__ import annotations

from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset
from gymnast.policy.sft import DemoSet
from gymnast.world_model.base import WorldModel, load_world_model, placed, rollout
from gymnast.world_model.views import model_cameras

IMAGINE_BATCH = 32  # episodes re-imagined together: one world-model call per step for all of them


def require_same_cameras(dataset: EpisodeDataset, model: WorldModel, wm: Path | str, remedy: str) -> None:
    """Raises ValueError, naming both and `remedy`, when `model` imagines other cameras than `dataset` is read with."""
    imagines = model_cameras(model)
    if (len(dataset.cameras) > 1 or imagines) and tuple(dataset.cameras) != imagines:
        raise ValueError(f"{dataset.root} is read with cameras {','.join(dataset.cameras)}, but the world model {wm} "
                         f"imagines {','.join(imagines) or 'one camera'}: {remedy}")


def reimagine(model: WorldModel, first_frames: list[torch.Tensor], actions: list[torch.Tensor],
              progress: bool = False) -> list[torch.Tensor]:
    """Each episode's video as `model` imagines it under the episode's actions.

    Args:
        first_frames: per episode, (H, W, 3) uint8 its real first frame.
        actions: per episode, (T, A) its actions.

    Returns:
        per episode, (T+1, H, W, 3) uint8: the real first frame, then one imagined frame per action.
    """
    # Episodes of similar length share a batch; shorter ones are padded with zero actions at the
    # end and cut back, which changes none of their frames: frame t follows actions up to t only.
    order = sorted(range(len(actions)), key=lambda n: len(actions[n]))
    videos: dict[int, torch.Tensor] = {}
    for first in tqdm(range(0, len(order), IMAGINE_BATCH), desc="imagining episodes", disable=not progress):
        batch = order[first: first + IMAGINE_BATCH]
        longest = max(len(actions[n]) for n in batch)
        padded = torch.stack([torch.nn.functional.pad(actions[n].float(), (0, 0, 0, longest - len(actions[n])))
                              for n in batch])
        start = torch.stack([first_frames[n][None] for n in batch])  # (b, 1, H, W, 3)
        frames = rollout(model, start, actions=padded).frames  # (b, T_max, H, W, 3)
        for n, video in zip(batch, frames):
            videos[n] = torch.cat([first_frames[n][None], video[: len(actions[n])]])
    return [videos[n] for n in range(len(actions))]


def imagined_demos(dataset: EpisodeDataset, indices: list[int], demos: DemoSet, chunk_size: int, wm: Path,
                   device: torch.device | None = None) -> DemoSet:
    """The demonstrations as a policy sees them in imagination: each episode re-imagined by the world
    model `wm` under its own actions, its frames paired with the same instruction, state and next
    actions as the real frames in `demos` (`load_demos` of the same `indices`).

    Only the frames a policy reads in imagination are kept, one per action chunk (t = 0, K, 2K...):
    it acts a chunk at a time and reads the frame after each, so those are the frames whose drawing
    it must act well on.
    """
    model = placed(load_world_model(wm), device or torch.device("cpu"))
    require_same_cameras(dataset, model, wm, "imagine the demonstrations with a world model of the policy's "
                         "cameras (`gymnast train-wm --cameras`)")
    if model.image_size != demos.images.shape[1]:
        raise ValueError(f"the world model {wm} draws {model.image_size} px frames, but the policy reads "
                         f"{demos.images.shape[1]} px ones from {dataset.root}; imagine with a world model of the "
                         f"policy's image size")
    episodes = [dataset.load(i) for i in indices]
    actions = [torch.from_numpy(episode.actions).float() for episode in episodes]
    videos = reimagine(model, [torch.from_numpy(episode.observed_frames[0]) for episode in episodes], actions)
    images = torch.cat([video[: len(steps)] for video, steps in zip(videos, actions)])  # frame t, before action t
    read = torch.cat([torch.arange(len(steps)) % chunk_size == 0 for steps in actions])
    if len(images) != len(demos.images):
        raise ValueError(f"{dataset.root}: the demonstrations hold {len(demos.images)} frames but their episodes "
                         f"{len(images)} actions")
    return DemoSet(images[read], demos.chunks[read], demos.valid[read], demos.instruction[read], demos.instructions,
                   demos.episodes, None if demos.states is None else demos.states[read])
