"""Side-by-side previews: real | imagined | amplified difference."""

import numpy as np
import pytest
from PIL import Image

from gymnast.utils.video import decode_video
from gymnast.world_model.videos import DIFFERENCE_GAIN, side_by_side, write_gif, write_side_by_side


def test_panels_show_real_imagined_and_the_amplified_difference():
    real = np.full((2, 8, 8, 3), 100, np.uint8)
    imagined = real.copy()
    imagined[:, 0, 0] = 110
    panel = side_by_side(real, imagined)
    assert panel.shape == (2, 8, 3 * 8 + 2 * 2, 3)
    assert np.array_equal(panel[:, :, :8], real) and np.array_equal(panel[:, :, 10:18], imagined)
    assert panel[0, 0, 20, 0] == 10 * DIFFERENCE_GAIN and panel[0, 1, 20, 0] == 0


def test_mismatched_shapes_are_rejected():
    with pytest.raises(ValueError, match=r"\(2, 8, 8, 3\) and \(3, 8, 8, 3\)"):
        side_by_side(np.zeros((2, 8, 8, 3), np.uint8), np.zeros((3, 8, 8, 3), np.uint8))


def test_video_and_gif_files_hold_every_frame(tmp_path):
    frames = np.random.default_rng(0).integers(0, 255, (5, 16, 16, 3), dtype=np.uint8)
    video = decode_video(write_side_by_side(tmp_path / "a.mp4", frames, frames, fps=10))
    assert video.shape == (5, 16, 16 * 3 + 4, 3)
    with Image.open(write_gif(tmp_path / "a.gif", frames, fps=10)) as gif:
        assert gif.n_frames == 5 and gif.size == (32, 32)
