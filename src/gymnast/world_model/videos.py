"""Side-by-side videos of real and imagined frames: real | imagined | difference.

People judge a world model faster by looking than by reading PSNR tables, so training writes
these periodically and eval-wm writes one per held-out episode; `write_gif` makes the small
looping versions shown in the docs.

Legend: T frames, H/W image size; frames are (T, H, W, 3) uint8.
"""

from __future__ import annotations

from io import BytesIO
from pathlib import Path

import numpy as np
from PIL import Image

from gymnast.utils.atomic import atomic_path, write_bytes
from gymnast.utils.video import BROWSER_CODEC, encode_video

DIFFERENCE_GAIN = 3  # small errors are invisible at 1x; 3x shows them without saturating everything
_GAP = 2  # white pixels between panels


def side_by_side(real: np.ndarray, imagined: np.ndarray) -> np.ndarray:
    """(T, H, 3W + 2 gaps, 3) uint8: real | imagined | |real - imagined| x DIFFERENCE_GAIN."""
    if real.shape != imagined.shape or real.ndim != 4 or real.shape[-1] != 3:
        raise ValueError(f"real and imagined must both be (T, H, W, 3), got {real.shape} and {imagined.shape}")
    difference = np.abs(real.astype(np.int16) - imagined.astype(np.int16)) * DIFFERENCE_GAIN
    gap = np.full((*real.shape[:2], _GAP, 3), 255, np.uint8)
    return np.concatenate([real, gap, imagined, gap, difference.clip(0, 255).astype(np.uint8)], axis=2)


def write_side_by_side(path: str | Path, real: np.ndarray, imagined: np.ndarray, fps: int) -> Path:
    """Writes the side-by-side video as an mp4 (atomically); returns its path."""
    frames = side_by_side(real, imagined)
    if frames.shape[1] % 2 or frames.shape[2] % 2:  # 4:2:0 needs even sizes
        frames = np.pad(frames, ((0, 0), (0, frames.shape[1] % 2), (0, frames.shape[2] % 2), (0, 0)), constant_values=255)
    with atomic_path(path) as tmp:
        encode_video(tmp, frames, fps=fps, codec=BROWSER_CODEC)
    return Path(path)


def write_gif(path: str | Path, frames: np.ndarray, fps: int, scale: int = 2) -> Path:
    """A looping GIF of (T, H, W, 3) uint8 frames, enlarged `scale` times (nearest neighbour)."""
    images = [Image.fromarray(f).resize((f.shape[1] * scale, f.shape[0] * scale), Image.NEAREST) for f in frames]
    buffer = BytesIO()
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0)
    write_bytes(path, buffer.getvalue())
    return Path(path)
