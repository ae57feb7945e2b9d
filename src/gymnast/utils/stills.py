"""Still frames of videos, in one picture: each row one video (or one tile of a video that holds
several side by side, as an RL run's group videos do), each column one frame index.

Watching a video shows one rollout at a time; a still sheet lays what several rollouts looked like
at the same moments next to each other, where a difference (an imagined arm turning to a smear,
a door that never opens) is seen at a glance.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from gymnast.utils.images import contact_sheet
from gymnast.utils.video import decode_video


def video_stills(videos: Sequence[str | Path], frames: Sequence[int], tiles: Sequence[int] = (0,),
                 tile_width: int = 0) -> Image.Image:
    """A sheet of each video's `frames`, one row per (video, tile); a frame past a video's end
    is its last one (episodes that ended early).

    Args:
        videos: mp4 files.
        frames: frame indices shown, in column order (frame t of an RL rollout video is the frame
            after t actions).
        tiles: which tiles of each video, counted from the left, when a video holds several
            rollouts side by side of `tile_width` pixels each.
        tile_width: the width of one tile; 0: the video is one tile.

    Raises:
        ValueError: no video or frame asked for, a negative frame, or a tile that a video is too
            narrow to hold (naming the file and its width).
    """
    if not videos or not frames:
        raise ValueError("stills need at least one video and one frame index")
    if min(frames) < 0:
        raise ValueError(f"frame indices must be >= 0, got {list(frames)}")
    if tile_width < 0:
        raise ValueError(f"tile_width must be >= 0, got {tile_width}")
    cells, labels = [], []
    for video in videos:
        decoded = decode_video(video)
        name = "/".join(Path(video).with_suffix("").parts[-3:])  # e.g. RUN/videos/step_000010
        count, _, width, _ = decoded.shape
        each = tile_width or width
        for tile in tiles:
            if tile < 0 or (tile + 1) * each > width:
                raise ValueError(f"{video}: {width} px wide holds {width // each} tile(s) of {each} px, "
                                 f"not tile {tile}")
            for frame in frames:
                shown = min(frame, count - 1)
                cells.append(np.ascontiguousarray(decoded[shown, :, tile * each:(tile + 1) * each]))
                labels.append(name + (f" #{tile}" if tile_width else "") + f", frame {shown}")
    return contact_sheet(cells, labels, columns=len(frames), scale=1)
