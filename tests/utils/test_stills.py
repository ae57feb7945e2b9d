"""Still sheets of videos: the right frame and tile in every cell, and clear errors."""

import numpy as np
import pytest

from gymnast.cli.app import main
from gymnast.utils.stills import video_stills
from gymnast.utils.video import encode_video

TILE = 32


@pytest.fixture
def group_video(tmp_path):
    """6 frames of two 32-px tiles: frame t of tile k is gray level 40 * t + 20 * k (no two alike)."""
    frames = np.zeros((6, TILE, 2 * TILE, 3), np.uint8)
    for t in range(6):
        for k in range(2):
            frames[t, :, k * TILE:(k + 1) * TILE] = 40 * t + 20 * k
    path = tmp_path / "group.mp4"
    encode_video(path, frames, fps=10)
    return path


def cell(sheet, row, column):
    """The mean gray level in the middle of a cell of a sheet of 32-px frames with 12-px captions."""
    pixels = np.asarray(sheet, dtype=float)
    top, left = row * (TILE + 12) + 12, column * TILE
    return pixels[top + 8:top + 24, left + 8:left + 24].mean()


def test_each_cell_holds_the_asked_frame_of_the_asked_tile_and_frames_past_the_end_show_the_last(group_video):
    sheet = video_stills([group_video], frames=[0, 2, 99], tiles=[1, 0], tile_width=TILE)
    assert sheet.size == (3 * TILE, 2 * (TILE + 12))
    expected = [[20, 100, 220], [0, 80, 200]]  # tile 1 then tile 0; frame 99 is frame 5
    for row in range(2):
        for column in range(3):
            assert cell(sheet, row, column) == pytest.approx(expected[row][column], abs=4)


def test_a_tile_the_video_cannot_hold_and_a_negative_frame_are_refused(group_video):
    with pytest.raises(ValueError, match=r"group.mp4: 64 px wide holds 2 tile\(s\) of 32 px, not tile 2"):
        video_stills([group_video], frames=[0], tiles=[2], tile_width=TILE)
    with pytest.raises(ValueError, match="frame indices must be >= 0"):
        video_stills([group_video], frames=[-1])


def test_the_command_writes_the_sheet_and_names_a_malformed_flag(group_video, tmp_path, capsys):
    out = tmp_path / "sheet.png"
    main(["stills", "--videos", str(group_video), "--out", str(out), "--frames", "0,5"])
    assert out.exists() and "stills:" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["stills", "--videos", str(group_video), "--out", str(out), "--frames", "0,x"])
    assert "--frames takes comma-separated integers, got '0,x'" in capsys.readouterr().err
