"""The own-robot walk-through on a dataset of three episodes: the default held-out fraction holds out no
scene, train-wm says so and which --heldout-fraction would, and eval-wm measures once it is given."""

from __future__ import annotations

import json

import pytest
from robot_datasets import write_robot_dataset

from gymnast.cli import main


@pytest.mark.slow
def test_three_episodes_hold_one_out_with_the_flag_train_wm_names(tmp_path, capsys, caplog):
    data = write_robot_dataset(tmp_path / "data", episodes=3, steps=12, height=24, width=32)
    main(["train-wm", "--data", str(data), "--out", str(tmp_path / "wm"), "--preset", "debug"])
    assert "has no held-out episodes at held-out fraction 0.1" in caplog.text
    with pytest.raises(SystemExit) as exit_info:
        main(["eval-wm", "--wm", str(tmp_path / "wm"), "--data", str(data), "--out", str(tmp_path / "eval.json")])
    error = capsys.readouterr().err
    assert exit_info.value.code == 2 and "train-wm --heldout-fraction" in error
    fraction = error.split("--heldout-fraction ")[1].split()[0]
    main(["train-wm", "--data", str(data), "--out", str(tmp_path / "wm2"), "--preset", "debug",
          "--heldout-fraction", fraction])
    main(["eval-wm", "--wm", str(tmp_path / "wm2"), "--data", str(data), "--out", str(tmp_path / "eval.json"),
          "--videos", "0", "--control-scenes", "0"])
    assert json.loads((tmp_path / "eval.json").read_text())["episodes"] == 1
