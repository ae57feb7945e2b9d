"""A camera's frames of one episode: decoded from its video or from images in its rows, matched to its rows.

Recorders do not always write one frame per data row: a video may be a few frames shorter or
longer than its rows, or start with its first frame twice. Within `frame_tolerance` frames the
frames are placed by their position (the first frame dropped where it is repeated, the last one
repeated or the extra ones dropped at the end) and the choice is recorded as a deviation; a larger
mismatch is an error naming the file. Images in the rows may be grayscale or 16-bit depth: they
become grey RGB frames.

Legend: L rows (frames) of one episode, N frames decoded, H/W image height/width.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator
from pathlib import Path

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from PIL import Image

from gymnast.data.deviations import Deviations
from gymnast.data.lerobot_format import DatasetError, EpisodeRef, MissingFile, require_columns
from gymnast.utils.video import VideoFile

_REPEAT_LEVEL = 1.0
"""Mean absolute difference (of 255) below which a video's first two frames are the same frame
recorded twice (a lossy codec does not reproduce a repeat bit for bit)."""


def frame_tolerance(n_rows: int) -> int:
    """How many frames a video may lack or have in excess of its L rows: one (LeRobot's timestamp
    tolerance), or a tenth of the rows for longer episodes (recorders that drop or add a few)."""
    return max(1, n_rows // 10)


def decode_episode(ref: EpisodeRef, rows: pa.Table, key: str, fps: float, notes: Deviations) -> np.ndarray:
    """The (L, H, W, 3) frames of camera feature `key` for the L rows of one episode.

    Raises:
        MissingFile: the video file is missing.
        DatasetError: it cannot be decoded, or its frames differ from the rows by more than the tolerance.
    """
    if ref.video_path is None:
        return decode_images(rows, key, ref.data_path, notes)
    n_rows = rows.num_rows
    start, end = ref.video_span
    if ref.rows is None:  # a file of its own (v2.x): read one frame past the rows, to tell a repeated first frame
        end = start + (n_rows + 1) / fps
    with _video(ref, key) as video:  # the counts are checked against the rows below, within the tolerance
        frames = video.decode(start, end, may_lack=n_rows + 1)
    if len(frames) > n_rows and _first_repeated(frames):
        notes.add(ref.video_path, key, "a video starts with its first frame twice", "the repeat is dropped")
        frames = frames[1:]
    return match_frames_to_rows(frames, n_rows, ref, key, notes)


def decode_range(ref: EpisodeRef, rows: pa.Table, key: str, fps: float, first: int, stop: int,
                 notes: Deviations) -> np.ndarray:
    """The (stop - first, H, W, 3) frames of rows [first, stop) of one episode, decoding those alone
    (a video from its key frame at or before `first`), placed as `decode_episode` places them."""
    if ref.video_path is None:
        return decode_images(rows.slice(first, stop - first), key, ref.data_path, notes)
    n_rows, rate = rows.num_rows, fps
    # A range to the end may lack frames the file does not have; a frame before it stands in for them.
    to_end = stop == n_rows
    lead = min(first, frame_tolerance(n_rows)) if to_end else 0
    with _video(ref, key) as video:  # one open for the probe and the range
        shift = 1 if ref.rows is None and _repeats_first(video, n_rows) else 0
        start, end = ref.video_span[0] + (first - lead + shift) / rate, ref.video_span[0] + (stop + shift) / rate
        frames = video.decode(start, end, may_lack=frame_tolerance(n_rows) if to_end else 0)
    wanted = stop - first + lead
    if len(frames) < wanted:
        if wanted - len(frames) > frame_tolerance(n_rows):
            raise DatasetError(f"{ref.video_path}: episode {ref.index} lacks frames {first}..{stop - 1} of its "
                               f"{n_rows} rows (more than {frame_tolerance(n_rows)} frames of tolerance)")
        frames = np.concatenate([frames, np.repeat(frames[-1:], wanted - len(frames), axis=0)])
    return frames[lead:]


def match_frames_to_rows(frames: np.ndarray, n_rows: int, ref: EpisodeRef, key: str = "",
                         notes: Deviations | None = None) -> np.ndarray:
    """The L frames of an episode's L rows from N frames, N within `frame_tolerance` of L.

    A video short of its rows repeats its last frame; one longer drops its extra frames at the end.
    LeRobot matches each row to the frame nearest its timestamp within one frame period, which for
    one frame too few or too many pairs the rows the same way.

    Raises:
        DatasetError: N and L differ by more than the tolerance (the message names the file).
    """
    source = ref.video_path or ref.data_path
    tolerance = frame_tolerance(n_rows)
    if abs(len(frames) - n_rows) > tolerance or not len(frames):
        camera = f"camera {key!r} of " if key else ""
        raise DatasetError(f"{source}: {camera}episode {ref.index} has {len(frames)} frames for {n_rows} data rows "
                           f"(more than the {tolerance} frame{'s' * (tolerance > 1)} of tolerance); re-encode the "
                           "video with one frame per row, or leave the episode out of meta/episodes")
    if len(frames) != n_rows:
        what = "short of" if len(frames) < n_rows else "longer than"
        decision = ("the last frame is repeated" if len(frames) < n_rows else "the extra frames at the end are dropped")
        found = f"episode {ref.index} has {len(frames)} frames for {n_rows} data rows (video {what} its rows)"
        (notes if notes is not None else Deviations()).add(source, key or "frames", found, f"matched by position within {tolerance} "
                                    f"frame{'s' * (tolerance > 1)}: {decision}")
        if len(frames) < n_rows:
            frames = np.concatenate([frames, np.repeat(frames[-1:], n_rows - len(frames), axis=0)])
        frames = frames[:n_rows]
    return frames


def decode_images(table: pa.Table, name: str, path: Path, notes: Deviations | None = None) -> np.ndarray:
    """Frames stored in the rows (LeRobot ``image`` features: structs of encoded image bytes), as
    (N, H, W, 3) uint8 RGB; grayscale images become grey RGB and 16-bit depth is scaled to 8 bits."""
    require_columns(table, [name], path)
    column = table.column(name).combine_chunks()
    if pa.types.is_struct(column.type) and column.type.get_field_index("bytes") >= 0:
        encoded = column.field("bytes").to_pylist()
    elif pa.types.is_binary(column.type) or pa.types.is_large_binary(column.type):
        encoded = column.to_pylist()
    else:
        raise DatasetError(f"{path}: field {name!r} has type {column.type}, expected struct<bytes, path> "
                           "of encoded images")
    images = []
    for data in encoded:
        if not isinstance(data, bytes):
            raise DatasetError(f"{path}: field {name!r} has a row without image bytes")
        try:
            images.append(_to_rgb(Image.open(io.BytesIO(data)), path, name, notes if notes is not None else Deviations()))
        except (OSError, ValueError, Image.DecompressionBombError) as e:
            raise DatasetError(f"{path}: field {name!r}: cannot decode an image: {e}") from e
    if not images or len({image.shape for image in images}) > 1:
        raise DatasetError(f"{path}: field {name!r} holds {len(images)} images of sizes "
                           f"{sorted({image.shape for image in images})}; one size per camera is needed")
    return np.stack(images)


def _to_rgb(image: Image.Image, path: Path, name: str, notes: Deviations) -> np.ndarray:
    if image.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        notes.add(path, name, f"images of mode {image.mode} (depth or 16-bit)",
                  "scaled to 8-bit grey (value / 256, clipped) and repeated to 3 channels")
        values = np.asarray(image, dtype=np.float64) / 256
        return np.repeat(np.clip(values, 0, 255).astype(np.uint8)[..., None], 3, axis=-1)
    if image.mode in ("L", "LA", "1"):
        notes.add(path, name, f"images are grayscale (mode {image.mode})", "repeated to 3 channels")
    return np.asarray(image.convert("RGB"))


@contextlib.contextmanager
def _video(ref: EpisodeRef, key: str) -> Iterator[VideoFile]:
    """The episode's video file, open; what opening or decoding it raises becomes an error naming the
    episode and the field (the body decodes, and raises nothing of its own)."""
    try:
        with VideoFile(ref.video_path) as video:
            yield video
    except FileNotFoundError as e:
        raise MissingFile(f"episode {ref.index}, field {key!r}: {e}") from e
    except (ValueError, OSError, av.error.FFmpegError) as e:  # VideoFile's messages name the file
        raise DatasetError(f"episode {ref.index}, field {key!r}: {e}") from e
    except (AttributeError, TypeError, IndexError) as e:  # PyAV meeting a damaged stream description
        raise DatasetError(f"episode {ref.index}, field {key!r}: {ref.video_path}: cannot decode video: {e}") from e


def _first_repeated(frames: np.ndarray) -> bool:
    return len(frames) > 1 and np.abs(frames[0].astype(np.int16) - frames[1]).mean() < _REPEAT_LEVEL


def _repeats_first(video: VideoFile, n_rows: int) -> bool:
    """Whether an episode's own video holds one frame more than its rows and starts with a repeat
    (decided as `decode_episode` decides it): the stream's declared frame count, read with the open,
    says whether the first two frames need decoding, which only such a video pays for."""
    if video.frames != n_rows + 1:
        return False
    try:
        return _first_repeated(video.decode(0.0, 2 / video.rate))
    except (OSError, ValueError, AttributeError, TypeError, IndexError, av.error.FFmpegError):
        return False  # the decode that follows names the file


def lacking_frames(refs: list[EpisodeRef], key: str) -> str | None:
    """What keeps the episodes from having frames of camera `key` (a missing video file or image
    column, named), or None when every episode has them."""
    for path in dict.fromkeys(ref.video_path for ref in refs if ref.video_path is not None):
        if not path.is_file():
            return f"video file {path} does not exist"
    if refs and refs[0].video_path is None and refs[0].data_path.is_file():
        path = refs[0].data_path  # image features are columns, and every data file has the same ones
        try:
            names = pq.read_schema(path).names
        except (pa.ArrowException, OSError) as e:
            raise DatasetError(f"{path}: cannot read parquet file: {e}") from e
        if key not in names:
            return f"{path} has no field {key!r}"
    return None
