"""RL on a policy of several cameras: the real world renders its views; a one-camera world model refuses it."""

from __future__ import annotations

import json

import pytest

from gymnast.cli import main

from rl_helpers import WORLD_MODEL


def test_rl_practises_a_two_camera_policy_in_the_real_world_but_not_in_a_one_camera_world_model(
        two_camera_demos, tmp_path, capsys):
    policy = tmp_path / "policy"
    main(["sft", "--data", str(two_camera_demos), "--out", str(policy), "--preset", "debug", "--cameras", "front,gripper"])
    common = ["rl", "--policy", str(policy), "--data", str(two_camera_demos), "--preset", "debug", "--tasks", "reach-v3"]
    main([*common, "--env", "sim", "--reward", "sim-dense", "--out", str(tmp_path / "sim")])
    summary = json.loads((tmp_path / "sim" / "summary.json").read_text())
    assert summary["steps"] == 2 and summary["eval_real_interactions"] > 0
    with pytest.raises(SystemExit):
        main([*common, "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", "verified", "--out", str(tmp_path / "wm")])
    assert "the world model imagines one camera's frames" in capsys.readouterr().err
