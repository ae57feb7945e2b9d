"""`--camera` on the commands that read a dataset's frames: it reaches the dataset reader."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gymnast.cli import main

WM = Path(__file__).resolve().parents[1] / "results" / "world_model" / "wm"


@pytest.mark.parametrize("command", [
    ["train-wm", "--preset", "debug"], ["sft", "--preset", "debug"], ["train-judge", "--preset", "debug"],
    ["eval-wm", "--wm", str(WM)]])
def test_a_camera_the_dataset_lacks_is_named_before_anything_runs(command, tiny_dataset, tmp_path, capsys):
    out = tmp_path / ("report.json" if command[0] == "eval-wm" else "run")
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--data", str(tiny_dataset), "--out", str(out), "--camera", "wrist"])
    assert exit_info.value.code == 2
    assert "no feature 'observation.images.wrist' for camera 'wrist'" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


def test_the_chosen_camera_trains_and_is_saved_with_the_run(tiny_dataset, tmp_path, capsys):
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(tmp_path / "wm"), "--preset", "debug", "--camera", "front"])
    assert json.loads((tmp_path / "wm" / "config.json").read_text())["train"]["camera"] == "front"
    main(["train-wm", "--out", str(tmp_path / "wm"), "--resume"])  # the camera comes from the run too
    capsys.readouterr()
