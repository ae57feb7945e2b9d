"""Encode RGB frames to mp4 and decode them back, frame-exactly, and measure what the codec changed.

Legend: N frames, H/W image height/width; frames are (N, H, W, 3) uint8 RGB.

The default codec is H.264 with ``qp=0`` in 4:4:4 (``yuv444p``): the encoder is lossless, so the
only error is the 8-bit RGB -> YCbCr -> RGB round trip, about 52.4 dB PSNR on the worst frame of
Meta-World renders, far above the 40 dB a world model needs; every H.264 decoder that supports
the High 4:4:4 profile (FFmpeg, VLC, mpv) plays it. ``docs/dataset_format.md`` lists the measured
alternatives; ``benchmarks/video_codec.py`` re-measures them.

A file may hold many episodes back to back (LeRobot v3). `encode_video` can force a key frame at
each episode start, so `decode_video` seeks straight to an episode and decodes nothing before it.
Frames are told apart by their presentation time, never by counting, so a range decodes exactly
the frames whose timestamps fall inside it.
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import NamedTuple

import av
import numpy as np
from av.video.frame import PictureType
from av.video.reformatter import VideoReformatter

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class VideoCodec:
    """How frames are compressed.

    Attributes:
        codec: FFmpeg encoder name, e.g. ``libx264``, ``libx264rgb`` or ``libsvtav1``.
        pix_fmt: pixel format of the encoded stream, e.g. ``yuv444p``, ``yuv420p`` or ``rgb24``.
        options: encoder options, e.g. ``{"qp": "0"}`` (lossless) or ``{"crf": "18"}``.
    """

    codec: str = "libx264"
    pix_fmt: str = "yuv444p"
    options: Mapping[str, str] = field(default_factory=lambda: {"qp": "0"})


CODEC_PRESETS: dict[str, VideoCodec] = {
    "h264-yuv444-lossless": VideoCodec(),
    "h264-rgb-lossless": VideoCodec("libx264rgb", "rgb24", {"qp": "0"}),
    "h264-yuv444-crf4": VideoCodec("libx264", "yuv444p", {"crf": "4"}),
    "h264-yuv420-crf18": VideoCodec("libx264", "yuv420p", {"crf": "18"}),
}
"""Named codecs: the default, a bit-exact one (RGB H.264, less widely playable), a smaller lossy
one that still clears 40 dB, and the common web default (below 40 dB on small renders)."""

DEFAULT_CODEC = CODEC_PRESETS["h264-yuv444-lossless"]
BROWSER_CODEC = CODEC_PRESETS["h264-yuv420-crf18"]
"""For videos people watch (reports, previews, RL rollouts): browsers play H.264 only in 4:2:0, so
the dataset's lossless 4:4:4 default would not play there; fidelity is never measured on these."""


class PSNR(NamedTuple):
    """Peak signal-to-noise ratio in dB (infinite where the images are identical).

    Attributes:
        per_frame: (N,) PSNR of each frame.
        mean: PSNR of the mean squared error over all frames (not the mean of ``per_frame``,
            which would be infinite as soon as one frame is exact).
    """

    per_frame: np.ndarray
    mean: float


def psnr(a: np.ndarray, b: np.ndarray) -> PSNR:
    """PSNR between two uint8 images or stacks of frames of the same shape.

    Args:
        a: (N, H, W, C) or (H, W, C) uint8.
        b: the same shape as ``a``.

    Returns:
        `PSNR` with one value per frame (a single image counts as one frame).
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"psnr needs equal shapes, got {a.shape} and {b.shape}")
    if a.dtype != np.uint8 or b.dtype != np.uint8:
        raise ValueError(f"psnr needs uint8 images, got {a.dtype} and {b.dtype}")
    if a.ndim == 3:
        a, b = a[None], b[None]
    mse = ((a.astype(np.float64) - b.astype(np.float64)) ** 2).reshape(len(a), -1).mean(axis=1)  # (N,)
    with np.errstate(divide="ignore"):
        per_frame = 10.0 * np.log10(255.0**2 / mse)
        mean = float(10.0 * np.log10(255.0**2 / mse.mean()))
    return PSNR(per_frame, mean)


def encode_video(
    path: str | Path,
    frames: np.ndarray,
    fps: int,
    codec: VideoCodec = DEFAULT_CODEC,
    keyframes: Collection[int] = (),
) -> None:
    """Encode RGB frames into an mp4 file (frame i is shown at time i / fps).

    Args:
        path: output file (parent directories are created); written in mp4 format whatever its
            extension, so it can be a temporary name.
        frames: (N, H, W, 3) uint8 RGB, N >= 1.
        fps: frames per second, a positive integer.
        codec: encoder, pixel format and options.
        keyframes: frame indices that must be key frames (each episode start in a shared file), so
            a reader can seek to them exactly. Frame 0 always is one.
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8 or len(frames) == 0:
        raise ValueError(f"frames must be (N, H, W, 3) uint8 with N >= 1, got {frames.shape} {frames.dtype}")
    if not isinstance(fps, int) or isinstance(fps, bool) or fps <= 0:
        raise ValueError(f"fps must be a positive int, got {fps!r}")
    _, height, width, _ = frames.shape
    if "420" in codec.pix_fmt and (height % 2 or width % 2):
        raise ValueError(f"pix_fmt {codec.pix_fmt} needs an even height and width, got {height}x{width}")
    forced = {int(k) for k in keyframes}
    time_base = Fraction(1, fps)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), mode="w", format="mp4") as container:
        stream = container.add_stream(codec.codec, rate=fps, options=dict(codec.options))
        stream.width, stream.height, stream.pix_fmt = width, height, codec.pix_fmt
        for i, image in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts, frame.time_base = i, time_base
            if i in forced:
                frame.pict_type = PictureType.I
            container.mux(stream.encode(frame))
        container.mux(stream.encode())  # flush the encoder's delayed frames


def decode_video(path: str | Path, start: float = 0.0, end: float | None = None, may_lack: int = 0) -> np.ndarray:
    """Decode the frames of an mp4 whose timestamps lie in ``[start, end)``.

    Timestamps are matched to the frame grid of the stream (half a frame of tolerance), so
    ``start = k / fps`` and ``end = (k + n) / fps`` return exactly frames k .. k + n - 1.

    Args:
        path: the video file.
        start: time of the first frame wanted, in seconds.
        end: time just after the last frame wanted, in seconds; None decodes to the end.
        may_lack: how many frames the range may lack at its end without it being an error (a
            recorder that wrote a frame fewer than it logged); 0 is strict.

    Returns:
        (N, H, W, 3) uint8 RGB frames.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: the file cannot be decoded, or holds fewer frames than the range asks for
            (a truncated file); the message names the file.
    """
    with VideoFile(path) as video:
        return video.decode(start, end, may_lack)


class VideoFile:
    """An mp4 opened once to decode several ranges of its first video stream (`decode_video` for each).

        with VideoFile(path) as video:
            if video.frames == 61: first_two = video.decode(0.0, 2 / video.rate)
            frames = video.decode(10 / video.rate, 20 / video.rate)

    Attributes:
        path: the video file.
        rate: frames per second of the stream.
        frames: the number of frames the stream declares (0 where it declares none).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: it cannot be opened or has no video stream with a frame rate (the message names it).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"video file not found: {self.path}")
        try:
            self._container = av.open(str(self.path))
        except av.error.FFmpegError as e:
            raise ValueError(f"{self.path}: cannot decode video: {e}") from e
        try:
            if not self._container.streams.video:
                raise ValueError(f"{self.path}: no video stream")
            self._stream = self._container.streams.video[0]
            rate = self._stream.average_rate or self._stream.guessed_rate
            if not rate:
                raise ValueError(f"{self.path}: the video stream has no frame rate")
        except BaseException:
            self._container.close()
            raise
        self.rate: Fraction = rate
        self.frames: int = self._stream.frames
        self._decoded = False

    def decode(self, start: float = 0.0, end: float | None = None, may_lack: int = 0) -> np.ndarray:
        """The (N, H, W, 3) uint8 RGB frames whose timestamps lie in ``[start, end)``, as `decode_video`.

        Raises:
            ValueError: as `decode_video`.
        """
        first = round(Fraction(start) * self.rate)
        stop = None if end is None else round(Fraction(end) * self.rate)
        try:
            if self._decoded and first == 0:
                self._container.seek(0, stream=self._stream)  # back to the start after an earlier range
            self._decoded = True
            frames = _decode_range(self._container, self._stream, self.rate, first, stop, self.path)
        except av.error.FFmpegError as e:
            raise ValueError(f"{self.path}: cannot decode video: {e}") from e
        wanted = (self.frames - first if self.frames else None) if stop is None else stop - first
        if wanted is not None and not wanted - may_lack <= len(frames) <= wanted:
            raise ValueError(
                f"{self.path}: expected {wanted} frames from t={start:.4f}s to "
                f"{'the end' if end is None else f't={end:.4f}s'}, decoded {len(frames)} (truncated file?)"
            )
        if not frames:
            raise ValueError(f"{self.path}: no frames in [{start}, {end})")
        return np.stack(frames)

    def close(self) -> None:
        self._container.close()

    def __enter__(self) -> VideoFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _decode_range(container, stream, rate: Fraction, first: int, stop: int | None, path: Path) -> list:
    """Decode frames with grid index in [first, stop); seeks to the key frame at or before first."""
    if first > 0:
        container.seek(int(first / rate / stream.time_base), stream=stream)
    frames: list[np.ndarray] = []
    # One converter for the whole range: `frame.to_ndarray(format=...)` builds a fresh swscale
    # context for every frame (a 96x96 frame decoded in 2.5 ms that way, 0.54 ms with one converter;
    # benchmarks/video_decode.py).
    to_rgb = VideoReformatter()
    for frame in container.decode(stream):
        if frame.pts is None:
            raise ValueError(f"{path}: a decoded frame has no timestamp")
        index = round(frame.pts * frame.time_base * rate)
        if index < first:
            continue
        if stop is not None and index >= stop:
            break
        if index != first + len(frames):
            if not frames and first > 0:
                # The seek landed after the wanted frame (no key frame there): decode from the start.
                logger.debug("%s: seek to frame %d overshot to %d, decoding from 0", path, first, index)
                container.seek(0, stream=stream)
                return _decode_range(container, stream, rate, 0, stop, path)[first:]
            raise ValueError(f"{path}: frame {first + len(frames)} is missing (next decoded is {index})")
        frames.append(to_rgb.reformat(frame, format="rgb24").to_ndarray())
    return frames


def video_info(path: str | Path) -> dict:
    """The stream description LeRobot stores under ``features[<video key>]["info"]``."""
    path = Path(path)
    try:
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            return {
                "video.height": stream.height,
                "video.width": stream.width,
                "video.codec": stream.codec_context.name,
                "video.pix_fmt": stream.codec_context.pix_fmt,
                "video.is_depth_map": False,
                "video.fps": int(stream.average_rate),
                "video.channels": 3,
                "has_audio": bool(container.streams.audio),
            }
    except (av.error.FFmpegError, IndexError) as e:
        raise ValueError(f"{path}: cannot read the video stream: {e}") from e
