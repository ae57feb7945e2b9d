"""Fitting a camera's frames to a model's square image: the image size rule and the two fits.

Every model sees square S x S frames. Which S, and how a camera's H x W frames become S x S, is
decided here for every trainer and for everything that later reads real frames for a checkpoint
(eval-wm, imagined starts), so a model always sees frames prepared the way it was trained on:

- `model_image_size`: square frames of a size a model can take (a multiple of 8, at most
  `NATIVE_LIMIT`) set S, as Meta-World's always have; other frames (non-square, very large) are
  fitted to the size the preset asks for.
- `fit_frames`: ``resize`` scales the whole frame to S x S (everything stays in view, the aspect
  ratio changes); ``crop`` cuts the central square and scales it (the aspect ratio stays, the
  sides are lost).

Legend: N frames, H/W a camera's frame height/width, S the model's image side.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np
from PIL import Image

Fit = Literal["resize", "crop"]
FITS: tuple[str, ...] = get_args(Fit)

NATIVE_LIMIT = 256
"""The largest square frames a model adopts as they are; larger ones are fitted to the preset's size
(a model's cost grows with its pixels, and a 480 px world model would not train on a CPU)."""


def model_image_size(shape: tuple[int, ...], preset_size: int) -> int:
    """The side S of a model trained on frames of `shape` (H, W, 3); see the module docstring."""
    height, width = shape[:2]
    if height == width and height % 8 == 0 and height <= NATIVE_LIMIT:
        return height
    return preset_size


def fit_frames(frames: np.ndarray, size: int, fit: Fit) -> np.ndarray:
    """(N, H, W, 3) uint8 frames -> (N, size, size, 3) uint8 by `fit`; frames already that size are returned as they are.

    Raises:
        ValueError: `fit` is not one of `FITS`, or `frames` is not (N, H, W, 3) uint8.
    """
    if fit not in FITS:
        raise ValueError(f"fit must be one of {FITS}, got {fit!r}")
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be (N, H, W, 3) uint8, got {frames.shape} {frames.dtype}")
    height, width = frames.shape[1:3]
    if fit == "crop":
        side = min(height, width)
        top, left = (height - side) // 2, (width - side) // 2
        frames, height, width = frames[:, top : top + side, left : left + side], side, side
    if (height, width) == (size, size):
        return frames
    # PIL filters over the whole footprint of each output pixel when shrinking, so a 480 px frame
    # becomes a smooth 96 px one rather than an aliased sample of it.
    return np.stack([np.asarray(Image.fromarray(frame).resize((size, size), Image.BILINEAR)) for frame in frames])
