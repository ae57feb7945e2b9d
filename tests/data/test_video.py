"""gymnast.utils.video: codec fidelity, frame-exact ranges, errors that name the file."""

from __future__ import annotations

import re

import numpy as np
import pytest
from data_helpers import smooth_frames

from gymnast.utils.video import CODEC_PRESETS, VideoFile, decode_video, encode_video, psnr, video_info


def numbered_frames(n: int, size: int = 32) -> np.ndarray:
    """Frames that say their own index: a smooth image plus a block whose grey level is 4 * i."""
    frames = smooth_frames(n, size)
    frames[:, : size // 2, : size // 2] = (4 * np.arange(n) % 256).astype(np.uint8)[:, None, None, None]
    return frames


def frame_ids(frames: np.ndarray, size: int = 32) -> list[int]:
    return [round(float(f[2 : size // 2 - 2, 2 : size // 2 - 2].mean() / 4)) for f in frames]


def test_default_codec_round_trip_is_above_40db(tmp_path):
    frames = smooth_frames(30, 64)
    encode_video(tmp_path / "a.mp4", frames, fps=80)
    decoded = decode_video(tmp_path / "a.mp4")
    assert decoded.shape == frames.shape and decoded.dtype == np.uint8
    assert psnr(frames, decoded).per_frame.min() >= 45.0


def test_rgb_preset_is_bit_exact(tmp_path):
    frames = smooth_frames(10, 32)
    encode_video(tmp_path / "a.mp4", frames, fps=80, codec=CODEC_PRESETS["h264-rgb-lossless"])
    result = psnr(frames, decode_video(tmp_path / "a.mp4"))
    assert np.isinf(result.per_frame).all() and result.mean == np.inf


def test_video_info_describes_the_stream(tmp_path):
    encode_video(tmp_path / "a.mp4", smooth_frames(4, 32), fps=80)
    info = video_info(tmp_path / "a.mp4")
    assert info["video.codec"] == "h264" and info["video.pix_fmt"] == "yuv444p"
    assert (info["video.height"], info["video.width"], info["video.fps"]) == (32, 32, 80)


@pytest.mark.parametrize("keyframes", [(0, 13, 40), ()], ids=["episode-keyframes", "no-keyframes"])
def test_decoding_a_time_range_returns_exactly_its_frames(tmp_path, keyframes):
    frames = numbered_frames(60)
    encode_video(tmp_path / "a.mp4", frames, fps=80, keyframes=keyframes)
    assert frame_ids(decode_video(tmp_path / "a.mp4")) == list(range(60))
    for first, stop in [(0, 13), (13, 40), (40, 60), (14, 15), (59, 60), (21, 38)]:
        decoded = decode_video(tmp_path / "a.mp4", first / 80, stop / 80)
        assert frame_ids(decoded) == list(range(first, stop)), (first, stop)
        assert psnr(frames[first:stop], decoded).mean >= 45.0



@pytest.mark.parametrize("keyframes", [(0, 13, 40), ()], ids=["episode-keyframes", "no-keyframes"])
def test_one_open_video_decodes_several_ranges_as_separate_opens_do(tmp_path, keyframes):
    encode_video(tmp_path / "a.mp4", numbered_frames(60), fps=80, keyframes=keyframes)
    with VideoFile(tmp_path / "a.mp4") as video:
        assert (video.frames, video.rate) == (60, 80)
        for first, stop in [(0, 2), (21, 38), (0, 13), (59, 60), (0, 60), (14, 15)]:  # back to the start, and on
            assert frame_ids(video.decode(first / 80, stop / 80)) == list(range(first, stop)), (first, stop)

def test_psnr_per_frame_and_mean():
    a = np.zeros((2, 4, 4, 3), np.uint8)
    b = a.copy()
    b[1] = 1  # MSE 1 on frame 1 only
    result = psnr(a, b)
    assert result.per_frame[0] == np.inf
    assert result.per_frame[1] == pytest.approx(20 * np.log10(255))
    assert result.mean == pytest.approx(10 * np.log10(255**2 / 0.5))
    assert psnr(a[0], a[0]).mean == np.inf
    with pytest.raises(ValueError, match="equal shapes"):
        psnr(a, a[:1])


def test_truncated_video_raises_naming_the_file(tmp_path):
    path = tmp_path / "a.mp4"
    encode_video(path, smooth_frames(20, 32), fps=80)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(ValueError, match=re.escape(str(path))):
        decode_video(path)


def test_range_beyond_the_end_raises_naming_the_file(tmp_path):
    path = tmp_path / "a.mp4"
    encode_video(path, smooth_frames(10, 32), fps=80)
    with pytest.raises(ValueError, match=re.escape(str(path)) + ".*expected 10 frames"):
        decode_video(path, 5 / 80, 15 / 80)


def test_missing_video_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.mp4"):
        decode_video(tmp_path / "nope.mp4")


def test_bad_frames_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"\(N, H, W, 3\) uint8"):
        encode_video(tmp_path / "a.mp4", np.zeros((2, 8, 8, 3), np.float32), fps=80)
    with pytest.raises(ValueError, match="even"):
        encode_video(
            tmp_path / "a.mp4",
            np.zeros((2, 9, 8, 3), np.uint8),
            fps=80,
            codec=CODEC_PRESETS["h264-yuv420-crf18"],
        )
