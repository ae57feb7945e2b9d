"""RL on a policy of several cameras: the real world renders its views, a world model of the same
cameras imagines them, and a world model of other cameras refuses it."""

from __future__ import annotations

import json

import pytest

from gymnast.cli import main

from rl_helpers import WORLD_MODEL


@pytest.mark.slow
def test_rl_practises_a_two_camera_policy_for_real_and_in_a_world_model_of_its_cameras(two_camera_demos, tmp_path, capsys):
    policy, wm = tmp_path / "policy", tmp_path / "wm"
    main(["sft", "--data", str(two_camera_demos), "--out", str(policy), "--preset", "debug", "--cameras", "front,gripper"])
    main(["train-wm", "--data", str(two_camera_demos), "--out", str(wm), "--preset", "debug", "--cameras", "front,gripper"])
    common = ["rl", "--policy", str(policy), "--data", str(two_camera_demos), "--preset", "debug", "--tasks", "reach-v3"]
    main([*common, "--env", "sim", "--reward", "sim-dense", "--out", str(tmp_path / "sim")])
    summary = json.loads((tmp_path / "sim" / "summary.json").read_text())
    assert summary["steps"] == 2 and summary["eval_real_interactions"] > 0
    main([*common, "--env", "imagined", "--wm", str(wm), "--reward", "verified", "--keyframes", "uniform",
          "--horizon", "10", "--eval-horizon", "10", "--out", str(tmp_path / "imagined")])
    summary = json.loads((tmp_path / "imagined" / "summary.json").read_text())
    assert summary["steps"] == 2 and summary["real_interactions"] == 0
    with pytest.raises(SystemExit):
        main([*common, "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", "verified", "--out", str(tmp_path / "one")])
    assert "sees front,gripper side by side, but the world model" in capsys.readouterr().err
