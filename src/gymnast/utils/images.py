"""Frames put side by side: several cameras' views as one observation, and contact sheets (many
frames on one labelled image, for people who would rather look than read); and repeated frames
found, so that whatever is computed per frame is computed once for a run of equal frames (a world
model of one frame per chunk repeats each for the chunk's other actions; a video repeats its last
frame after its episode ends)."""

from __future__ import annotations

from io import BytesIO
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from PIL import Image, ImageDraw

from gymnast.utils.atomic import write_bytes


def tile_views(views: Sequence[np.ndarray]) -> np.ndarray:
    """Several cameras' (..., H, W, 3) frames of one instant (or of one episode) side by side: (..., H, V*W, 3).

    One view is returned as it is. Views travel tiled because every pipe of the rollout engine,
    the videos and the datasets' episodes carries one frame per step; a model that sees several
    views splits the frame back into V squares (`gymnast.policy.observation`).

    Raises:
        ValueError: no view, or views of different shapes.
    """
    if not views:
        raise ValueError("tile_views needs at least one view")
    shapes = {tuple(view.shape) for view in views}
    if len(shapes) > 1:
        raise ValueError(f"views to tile need one shape, got {sorted(shapes)}")
    return views[0] if len(views) == 1 else np.concatenate(list(views), axis=-2)


def split_views(images: torch.Tensor, views: int) -> torch.Tensor:
    """(N, ..., H, V*W, C) images of V cameras side by side -> (N*V, ..., H, W, C): each camera's
    square on its own, an item's V views consecutive (`tile_views` puts them side by side;
    `join_views` undoes this)."""
    if views == 1:
        return images
    *lead, height, width, channels = images.shape
    if images.ndim < 4 or width % views:
        raise ValueError(f"images {tuple(images.shape)} are not {views} views side by side")
    squares = images.reshape(*lead, height, views, width // views, channels)  # (N, ..., H, V, W, C)
    return squares.movedim(-3, 1).flatten(0, 1)


def changed_frames(videos: torch.Tensor) -> torch.Tensor:
    """(N, T) bool on the host for (N, T, ...) videos: True where a frame differs from the one
    before it, and at t = 0."""
    changed = torch.ones(videos.shape[:2], dtype=torch.bool)
    changed[:, 1:] = (videos[:, 1:] != videos[:, :-1]).flatten(2).any(2).cpu()
    return changed


def latest_changed(changed: torch.Tensor) -> torch.Tensor:
    """(N, T) int64 for (N, T) `changed_frames`: each frame's latest changed frame at or before it,
    so that values computed on the changed frames alone reach their repeats by ``gather(1, ...)``."""
    return torch.cummax(torch.where(changed, torch.arange(changed.shape[1]), 0), dim=1).values


def join_views(images: torch.Tensor, views: int) -> torch.Tensor:
    """(N*V, ..., H, W, C), an item's V views consecutive -> (N, ..., H, V*W, C) side by side:
    the inverse of `split_views`."""
    if views == 1:
        return images
    if images.ndim < 4 or images.shape[0] % views:
        raise ValueError(f"images {tuple(images.shape)} do not hold {views} views of each item")
    return images.unflatten(0, (-1, views)).movedim(1, -3).flatten(-3, -2)


def contact_sheet(
    frames: Sequence[np.ndarray],
    labels: Sequence[str] = (),
    columns: int = 5,
    scale: int = 2,
) -> Image.Image:
    """Tiles equally sized (H, W, 3) uint8 frames into a grid, each with an optional caption.

    Args:
        frames: the images, row by row.
        labels: one caption per frame (or none).
        columns: frames per row.
        scale: nearest-neighbour upscaling, so small frames stay legible without blurring.
    """
    if not frames:
        raise ValueError("contact_sheet needs at least one frame")
    height, width = frames[0].shape[:2]
    for i, frame in enumerate(frames):
        if frame.shape != (height, width, 3) or frame.dtype != np.uint8:
            raise ValueError(f"frame {i} has shape {frame.shape} {frame.dtype}, expected ({height}, {width}, 3) uint8")
    caption = 12 if labels else 0
    cell_w, cell_h = width * scale, height * scale + caption
    rows = -(-len(frames) // columns)
    sheet = Image.new("RGB", (cell_w * min(columns, len(frames)), cell_h * rows), "white")
    draw = ImageDraw.Draw(sheet)
    for i, frame in enumerate(frames):
        x, y = (i % columns) * cell_w, (i // columns) * cell_h
        tile = Image.fromarray(frame).resize((width * scale, height * scale), Image.NEAREST)
        sheet.paste(tile, (x, y + caption))
        if labels:
            draw.text((x + 2, y), labels[i], fill="black")
    return sheet


def save_png(image: Image.Image, path: str | Path) -> Path:
    """Writes a PNG atomically (a crash never leaves a truncated picture)."""
    buffer = BytesIO()
    image.save(buffer, format="PNG")
    write_bytes(path, buffer.getvalue())
    return Path(path)
