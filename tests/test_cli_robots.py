"""A user's own robot: LeRobot datasets of other robots go through train-wm, sft, train-judge and eval-wm
from the command line, with no code change; what cannot work is refused by name before training."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from robot_datasets import write_robot_dataset

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.policy.load import load_policy
from gymnast.world_model.base import load_world_model

ROBOTS = {
    # 6 episodes: the scene hash holds out episodes 4 and 5, so eval-wm has some to measure.
    "v2.1, 26-D actions, 120x160 at 10 fps": dict(version="v2.1", action_dim=26, fps=10, action_scale=3.0),
    "v3.0, 7-D actions at 30 fps, a video one frame short": dict(version="v3.0", action_dim=7, fps=30, short_video=True),
    "v2.0, two cameras, the first without video": dict(version="v2.0", action_dim=7, cameras=("wrist", "front"),
                                                       without_video=("wrist",)),
}


FIRST = next(iter(ROBOTS))


def _train_every_model(root: Path, robot: str) -> dict[str, Path]:
    """The robot's dataset (6 episodes of 10 steps) and train-wm, sft and train-judge on it, debug presets."""
    paths = {"data": write_robot_dataset(root / "data", episodes=6, steps=10, **ROBOTS[robot])}
    for command in ("train-wm", "sft", "train-judge"):
        paths[command] = root / command
        main([command, "--data", str(paths["data"]), "--out", str(paths[command]), "--preset", "debug"])
    return paths


@pytest.fixture(scope="module")
def robot_models(tmp_path_factory) -> dict[str, Path]:
    """The first robot's dataset (26-D actions, 120x160 frames, v2.1) and the three models trained on it."""
    return _train_every_model(tmp_path_factory.mktemp("robot"), FIRST)


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_another_robots_dataset_trains_every_model_with_the_debug_presets(robot, request, tmp_path, capsys):
    # The first robot's models are the ones the RL tests below practise with: trained once.
    models = request.getfixturevalue("robot_models") if robot == FIRST else _train_every_model(tmp_path, robot)
    stats = EpisodeDataset(models["data"]).action_stats

    wm = load_world_model(models["train-wm"])
    assert (wm.image_size, wm.action_dim) == (96, stats.dim)  # non-square frames are fitted to the preset's size
    assert (wm.config.action_low, wm.config.action_high) == stats.action_range()
    saved = json.loads((models["train-wm"] / "config.json").read_text())
    assert saved["train"]["fit"] == "resize" and saved["train"]["camera"] is None

    policy = load_policy(models["sft"])
    assert (policy.config.image_size, policy.action_dim) == (96, stats.dim)
    assert (policy.tokenizer.low, policy.tokenizer.high) == stats.action_range()
    saved_stats = json.loads(json.dumps(stats.to_dict()))  # as JSON keeps them, with the weights
    assert json.loads((models["sft"] / "config.json").read_text())["action_stats"] == saved_stats
    assert saved["action_stats"] == saved_stats

    judge = json.loads((models["train-judge"] / "config.json").read_text())
    assert judge["model"]["image_size"] == 96 and judge["train"]["fit"] == "resize"
    capsys.readouterr()


@pytest.mark.slow
def test_the_flow_world_model_takes_another_robots_actions_and_frames(tmp_path, capsys):
    data = write_robot_dataset(tmp_path / "data", episodes=6, steps=10, **ROBOTS[FIRST])
    main(["train-wm", "--backend", "flow", "--data", str(data), "--out", str(tmp_path / "wm"), "--preset", "debug"])
    wm = load_world_model(tmp_path / "wm")
    stats = EpisodeDataset(data).action_stats
    assert wm.backend == "flow" and (wm.image_size, wm.action_dim) == (96, stats.dim)
    assert wm.action_range == stats.action_range()
    capsys.readouterr()


@pytest.mark.slow
def test_eval_wm_fits_the_frames_as_the_world_model_was_trained(tmp_path, capsys):
    data = write_robot_dataset(tmp_path / "data", episodes=6, steps=10, height=64, width=48)
    main(["train-wm", "--data", str(data), "--out", str(tmp_path / "wm"), "--preset", "debug", "--fit", "crop"])
    assert json.loads((tmp_path / "wm" / "config.json").read_text())["train"]["fit"] == "crop"
    main(["eval-wm", "--wm", str(tmp_path / "wm"), "--data", str(data), "--out", str(tmp_path / "report.json")])
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["episodes"] == 2 and report["controllability"] == {}  # another robot's scenes have no simulator
    capsys.readouterr()


def _without_action(data: Path) -> None:
    info = json.loads((data / "meta/info.json").read_text())
    del info["features"]["action"]
    (data / "meta/info.json").write_text(json.dumps(info))


def _with_narrow_actions(data: Path) -> None:
    info = json.loads((data / "meta/info.json").read_text())
    info["features"]["action"]["shape"] = [8]
    (data / "meta/info.json").write_text(json.dumps(info))


BAD = {
    "no action feature": (_without_action, ("train-wm", "sft", "train-judge"), "no 'action' feature in 'features'"),
    "no camera with video": (lambda data: None, ("train-wm", "sft", "train-judge"), "no camera has frames to read"),
    "actions narrower than declared": (_with_narrow_actions, ("train-wm", "sft"),
                                       "field 'action' has 7 values per row, info.json's 'action' feature says 8"),
}


@pytest.mark.parametrize("case", BAD)
def test_what_cannot_work_is_one_line_naming_the_field_before_training(case, tmp_path, capsys):
    damage, commands, message = BAD[case]
    without = ("front",) if case == "no camera with video" else ()
    data = write_robot_dataset(tmp_path / "data", episodes=2, steps=3, without_video=without)
    damage(data)
    for command in commands:
        out = tmp_path / command
        with pytest.raises(SystemExit) as exit_info:
            main([command, "--data", str(data), "--out", str(out), "--preset", "debug"])
        assert exit_info.value.code == 2
        error = capsys.readouterr().err
        assert message in error and "Traceback" not in error, command
        assert not out.exists() or not any(out.iterdir()), command


@pytest.mark.slow
@pytest.mark.parametrize("command, section", [("sft", "sft"), ("train-judge", "train")])
def test_the_frame_fit_is_a_flag_saved_with_the_run(command, section, tmp_path, capsys):
    data = write_robot_dataset(tmp_path / "data", episodes=6, steps=10, height=64, width=48)
    main([command, "--data", str(data), "--out", str(tmp_path / "run"), "--preset", "debug", "--fit", "crop"])
    assert json.loads((tmp_path / "run" / "config.json").read_text())[section]["fit"] == "crop"
    capsys.readouterr()


def _rl_on_robot(models: dict[str, Path], out: Path, *extra: str) -> None:
    main(["rl", "--policy", str(models["sft"]), "--env", "imagined", "--wm", str(models["train-wm"]),
          "--reward", f"judge:{models['train-judge']}", "--out", str(out), "--preset", "debug", *extra])


@pytest.mark.slow
def test_rl_in_imagination_practises_on_another_robots_own_tasks(robot_models, tmp_path, capsys):
    out = tmp_path / "rl"
    _rl_on_robot(robot_models, out, "--no-real-eval", "--watch-every", "0")
    summary = json.loads((out / "summary.json").read_text())
    assert [point["step"] for point in summary["curve"]] == [0, 2]
    assert summary["real_interactions"] == summary["eval_real_interactions"] == 0
    tasks = {info.task for info in EpisodeDataset(robot_models["data"]).episodes}
    assert set(summary["curve"][0]) >= {f"eval/own_success/{task}" for task in tasks}  # its own tasks, evaluated
    saved = json.loads((out / "config.json").read_text())
    assert saved["rl"]["tasks"] == ""
    keys = {"action_key": "action", "state_key": "observation.state"}  # the policy's, as sft saved them
    assert saved["frames"] == {"camera": None, "fit": "resize", "keys": keys}
    capsys.readouterr()


@pytest.mark.parametrize("extra, message", [
    ((), "add --no-real-eval --watch-every 0"),
    (("--no-real-eval", "--watch-every", "0", "--tasks", "fold the towel"), "has no task 'fold the towel'"),
])
def test_rl_on_another_robot_names_what_it_cannot_do(extra, message, robot_models, tmp_path, capsys):
    with pytest.raises(SystemExit):
        _rl_on_robot(robot_models, tmp_path / "rl", *extra)
    assert message in capsys.readouterr().err


def test_another_robots_two_cameras_train_a_policy_a_judge_and_a_world_model_that_see_both(tmp_path):
    data = write_robot_dataset(tmp_path / "data", episodes=6, steps=10, height=64, width=80, cameras=("top", "wrist"))
    main(["sft", "--data", str(data), "--out", str(tmp_path / "sft"), "--preset", "debug", "--cameras", "top,wrist"])
    policy = load_policy(tmp_path / "sft")
    assert policy.config.cameras == ("top", "wrist") and policy.observed_shape == (96, 192, 3)  # each fitted to 96
    main(["train-judge", "--data", str(data), "--out", str(tmp_path / "judge"), "--preset", "debug",
          "--cameras", "top,wrist"])
    assert json.loads((tmp_path / "judge" / "config.json").read_text())["model"]["cameras"] == ["top", "wrist"]
    main(["train-wm", "--data", str(data), "--out", str(tmp_path / "wm"), "--preset", "debug", "--cameras", "top,wrist"])
    model = load_world_model(tmp_path / "wm")
    assert model.cameras == ("top", "wrist") and model.image_size == 96  # each 64x80 view fitted to 96 px
    _, frames = model.step(model.init_state(torch.zeros(1, 1, 96, 192, 3, dtype=torch.uint8)), torch.zeros(1, 2, 7))
    assert frames.shape == (1, 2, 96, 192, 3)
