"""`gymnast imagination` and `gymnast rl-signal` measure a LeRobot policy (``--policy lerobot:PATH``)
as they measure gymnast's own: its imagined rollouts against their real replays; a policy that reads
the robot's state is given a state model's beside the world model (``--robot-state``)."""

import json
from pathlib import Path

import pytest

from gymnast.cli import main

RESULTS = Path(__file__).resolve().parents[2] / "results"
WORLD_MODEL = RESULTS / "world_model" / "wm"
JUDGE = RESULTS / "judge" / "one_camera" / "judge"
STATE_ENSEMBLE = RESULTS / "world_model" / "state_v5"


def test_imagination_replays_a_lerobot_policys_imagined_rollouts_for_real(lerobot_act, tmp_path):
    out = tmp_path / "imagination"
    main(["imagination", "--policy", f"lerobot:{lerobot_act}", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--tasks", "reach-v3", "--episodes", "1", "--horizon", "10", "--videos", "0", "--out", str(out)])
    report = json.loads((out / "imagination.json").read_text())
    assert report["settings"]["policy"] == f"lerobot:{lerobot_act}" and report["overall"]["episodes"] == 1


def test_rl_signal_measures_a_lerobot_policys_imagined_advantages_against_real_replays(lerobot_act, tmp_path):
    out = tmp_path / "signal"
    main(["rl-signal", "--policy", f"lerobot:{lerobot_act}", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--out", str(out), "--tasks", "reach-v3", "--starts-per-task", "1", "--group-size", "2", "--horizons", "10",
          "--batch", "2", "--workers", "1"])
    report = json.loads((out / "signal.json").read_text())
    assert len(report["rollouts"]) == 2 and report["interactions"] == 2 * 10  # each imagined rollout replayed for real


def test_a_policy_reading_the_robot_state_is_measured_with_a_state_model_beside_the_world_model(tmp_path, capsys):
    from gymnast.policy.lerobot_init import new_act

    folder = new_act(tmp_path / "act", chunk=5, predicted=8, action_std=0.5, state_dim=4)  # hand xyz and gripper
    policy = ["--policy", f"lerobot:{folder}", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}"]
    imagination = ["imagination", *policy, "--tasks", "reach-v3", "--episodes", "1", "--horizon", "10", "--videos", "0"]
    with pytest.raises(SystemExit):
        main([*imagination, "--out", str(tmp_path / "refused")])
    assert "imagines images only; give a state model that imagines it with --robot-state RUN" in capsys.readouterr().err
    main([*imagination, "--robot-state", str(STATE_ENSEMBLE), "--out", str(tmp_path / "imagination")])
    report = json.loads((tmp_path / "imagination" / "imagination.json").read_text())
    assert report["settings"]["robot_state"] == str(STATE_ENSEMBLE) and report["overall"]["episodes"] == 1

    main(["rl-signal", *policy, "--robot-state", str(STATE_ENSEMBLE), "--out", str(tmp_path / "signal"),
          "--tasks", "reach-v3", "--starts-per-task", "1", "--group-size", "2", "--horizons", "10", "--batch", "2",
          "--workers", "1"])
    report = json.loads((tmp_path / "signal" / "signal.json").read_text())
    assert len(report["rollouts"]) == 2 and report["interactions"] == 2 * 10


def test_a_state_model_for_a_policy_that_reads_no_state_is_refused(lerobot_act, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["imagination", "--policy", f"lerobot:{lerobot_act}", "--wm", str(WORLD_MODEL), "--reward",
              f"judge:{JUDGE}", "--robot-state", str(STATE_ENSEMBLE), "--out", str(tmp_path / "refused")])
    assert "reads none: leave --robot-state out" in capsys.readouterr().err
