"""Contact sheets: many frames on one labelled image, for people who would rather look than read."""

from __future__ import annotations

from io import BytesIO
from pathlib import Path
from typing import Sequence

import numpy as np
from PIL import Image, ImageDraw

from gymnast.utils.atomic import write_bytes


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
