"""World models of several cameras: one single-view model imagines each camera's view from its own
frames under the same actions, trained on every view, saved and measured per camera."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from gymnast.cli import main
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.utils.images import join_views, split_views
from gymnast.world_model.base import load_world_model
from gymnast.world_model.ensemble import EnsembleWorldModel
from gymnast.world_model.train import train_world_model, wm_preset
from gymnast.world_model.views import MultiViewWorldModel

TWO = ("front", "gripper")


def test_split_and_join_views_are_inverses_and_keep_each_cameras_square():
    frames = torch.randint(0, 256, (2, 3, 8, 24, 3), dtype=torch.uint8)  # 2 items, 3 frames, 3 views of 8 px
    squares = split_views(frames, 3)
    assert squares.shape == (6, 3, 8, 8, 3)
    assert torch.equal(squares[4], frames[1, :, :, 8:16])  # item 1's second view
    assert torch.equal(join_views(squares, 3), frames)
    with pytest.raises(ValueError, match="not 3 views side by side"):
        split_views(frames[..., :20, :], 3)


@pytest.fixture(scope="module")
def two_camera_wm(two_camera_demos, tmp_path_factory):
    run = tmp_path_factory.mktemp("wm") / "run"
    # Scenes held out for eval-wm: 4 episodes of one task need a large share to leave one out.
    config = dataclasses.replace(wm_preset("debug"), cameras=TWO, steps=6, heldout_fraction=0.6)
    train_world_model(two_camera_demos, run, config, progress=False)
    return run


def test_a_two_camera_world_model_imagines_each_view_as_its_one_view_model_would(two_camera_wm):
    model = load_world_model(two_camera_wm)
    assert isinstance(model, MultiViewWorldModel) and model.cameras == TWO and model.views == 2
    saved = json.loads((two_camera_wm / "config.json").read_text())
    assert saved["model"]["cameras"] == list(TWO) and saved["train"]["cameras"] == list(TWO)
    context = torch.randint(0, 256, (3, 2, 32, 64, 3), dtype=torch.uint8)
    actions = torch.rand(3, 4, 4) * 2 - 1
    _, frames = model.step(model.init_state(context), actions)
    assert frames.shape == (3, 4, 32, 64, 3)
    # The gripper view is the one-view model's imagination from the gripper frames alone.
    _, gripper = model.model.step(model.model.init_state(context[..., 32:, :]), actions)
    torch.testing.assert_close(frames[..., 32:, :], gripper)
    with pytest.raises(ValueError, match=r"\(B, C, 32, 64, 3\) uint8 \(2 views side by side\)"):
        model.init_state(context[..., :32, :])  # one camera's frames


def test_the_imagined_env_and_an_ensemble_take_the_views_side_by_side(two_camera_wm, two_camera_demos, tmp_path):
    model = load_world_model(two_camera_wm)
    env = BatchedImaginedEnv(model, num_envs=2, chunk_size=3, horizon=6)
    assert env.single_observation_space["image"].shape == (32, 64, 3)
    with pytest.raises(ValueError, match="the world model's 2 cameras side by side"):
        env.reset(options={"frames": torch.zeros(2, 32, 32, 3, dtype=torch.uint8).numpy(), "instructions": ["a", "b"]})
    second = tmp_path / "second"
    main(["train-wm", "--data", str(two_camera_demos), "--out", str(second), "--init", str(two_camera_wm),
          "--preset", "debug", "--cameras", "front,gripper", "--steps", "2", "--seed", "1"])
    ensemble = EnsembleWorldModel([model, load_world_model(second)])
    assert ensemble.cameras == TWO
    state = ensemble.init_state(torch.zeros(2, 1, 32, 64, 3, dtype=torch.uint8))
    state, frames = ensemble.step(state, torch.zeros(2, 3, 4))
    assert frames.shape == (2, 3, 32, 64, 3) and state.disagreement.shape == (2, 3)
    with pytest.raises(ValueError, match="cameras differ"):
        EnsembleWorldModel([model, model.model])  # a model of both views beside one of one view


def test_eval_wm_measures_each_cameras_view(two_camera_wm, two_camera_demos, tmp_path):
    out = tmp_path / "eval.json"
    main(["eval-wm", "--wm", str(two_camera_wm), "--data", str(two_camera_demos), "--out", str(out), "--videos", "0",
          "--control-scenes", "1"])
    report = json.loads(out.read_text())
    assert set(report["per_camera"]) == set(TWO)
    for figures in report["per_camera"].values():
        assert figures["psnr_h1"] > 0 and "copy_last_moving_psnr_h8" in figures
    assert report["controllability"]["scenes"] == 1  # replayed in the simulator with both cameras rendered


def test_a_judge_of_two_cameras_learns_from_their_re_imagined_views(two_camera_wm, two_camera_demos, tmp_path):
    run = tmp_path / "judge"
    main(["train-judge", "--data", str(two_camera_demos), "--out", str(run), "--preset", "debug", "--cameras",
          "front,gripper", "--wm", str(two_camera_wm)])
    saved = json.loads((run / "config.json").read_text())
    assert saved["model"]["cameras"] == list(TWO) and saved["wm"] == str(two_camera_wm)


def test_the_flow_backend_imagines_two_cameras_too(two_camera_demos, tmp_path):
    config = dataclasses.replace(wm_preset("debug", "flow"), cameras=TWO, heldout_fraction=0.0)
    train_world_model(two_camera_demos, tmp_path / "flow", config, progress=False)
    model = load_world_model(tmp_path / "flow")
    assert isinstance(model, MultiViewWorldModel) and type(model.model).__name__ == "FlowWorldModel"
    generator = torch.Generator().manual_seed(0)
    state = model.init_state(torch.zeros(2, 1, 32, 64, 3, dtype=torch.uint8), generator=generator)
    _, frames = model.step(state, torch.zeros(2, 3, 4), generator=generator)
    assert frames.shape == (2, 3, 32, 64, 3)
