"""Rollout videos of an RL run: one group's G rollouts side by side, each with its reward on it.

Legend: G rollouts in a group, T frames, H/W image size.

Watching what the policy was rewarded for is the fastest way to see reward hacking, so every
tile carries its score, and the video plays in a browser (H.264, 4:2:0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from PIL import Image, ImageDraw

from gymnast.envs.metaworld import CONTROL_FPS
from gymnast.rl.rollout import Rollouts
from gymnast.utils.atomic import atomic_path
from gymnast.utils.video import BROWSER_CODEC, encode_video

SCALE = 2  # 96-px frames are too small to read a caption on


def captioned(frames: np.ndarray, text: str, scale: int = SCALE) -> np.ndarray:
    """(T, H, W, 3) uint8 frames enlarged `scale` times, with `text` written in the top-left corner."""
    big = frames.repeat(scale, axis=1).repeat(scale, axis=2)
    out = np.empty_like(big)
    for t, frame in enumerate(big):
        image = Image.fromarray(frame)
        draw = ImageDraw.Draw(image)
        left, top, right, bottom = draw.textbbox((3, 2), text)
        draw.rectangle((left - 2, top - 1, right + 2, bottom + 1), fill=(0, 0, 0))
        draw.text((3, 2), text, fill=(255, 255, 255))
        out[t] = np.asarray(image)
    return out


def write_group_video(path: Path, rollouts: Rollouts, scores: torch.Tensor, group_size: int) -> Path:
    """Writes the first group's rollouts side by side, captioned with their rewards; returns `path`."""
    frames = rollouts.select(torch.arange(group_size)).frames.numpy()  # (G, T, H, W, 3)
    tiles = [captioned(video, f"r={score:.2f}") for video, score in zip(frames, scores[:group_size].tolist())]
    grid = np.concatenate(tiles, axis=2)  # (T, H, G * W, 3)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        encode_video(tmp, grid, fps=CONTROL_FPS, codec=BROWSER_CODEC)
    return path
