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
from gymnast.world_model.base import WorldModel, rollout
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
