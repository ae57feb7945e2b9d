"""How a state model is measured: over the whole state for another robot (its states have their own
layout), and also at the hand and the object for Meta-World's."""

from __future__ import annotations

import json

import pytest
import torch
from robot_datasets import write_robot_dataset

from gymnast.world_model.train_state import StateTrainConfig, train_state_model


def test_another_robots_state_model_reports_its_error_over_the_whole_state(tmp_path):
    data = write_robot_dataset(tmp_path / "data", episodes=10, steps=12, action_dim=6)
    out = tmp_path / "state"
    train_state_model(data, out, StateTrainConfig(steps=20, batch_size=8, unroll=4, heldout_fraction=0.3,
                                                  checkpoint_every=20), progress=False)
    report = json.loads((out / "eval.json").read_text())
    assert report["windows"] > 0
    for horizon in report["horizons"].values():
        assert horizon["state_rmse"] > 0  # the recorded states are noise: no model predicts them exactly
        assert "hand_cm" not in horizon and "object_cm" not in horizon and "linear_baseline_hand_cm" not in horizon


def test_a_meta_world_state_model_is_also_measured_at_the_hand_and_the_object(tiny_dataset):
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.policy.text import InstructionEncoder
    from gymnast.world_model.state_model import StateModel, StateModelConfig
    from gymnast.world_model.train_state import episode_tensors, evaluate_state_model

    dataset = EpisodeDataset(tiny_dataset)
    episodes = episode_tensors(dataset, list(range(len(dataset))), InstructionEncoder())
    report = evaluate_state_model(StateModel(StateModelConfig()).eval(), episodes, horizons=(8,))
    errors = report["horizons"]["8"]
    assert errors["hand_cm"] > 0 and errors["object_cm"] >= 0 and errors["state_rmse"] > 0


def test_a_state_model_fine_tunes_from_a_run_keeping_its_normalisation(tmp_path, capsys):
    from gymnast.cli import main
    from gymnast.utils.checkpoint import resolve_checkpoint
    from gymnast.world_model.state_model import load_state_model

    data = write_robot_dataset(tmp_path / "data", episodes=6, steps=12, action_dim=6)
    more = write_robot_dataset(tmp_path / "more", episodes=4, steps=12, action_dim=6, action_scale=3.0)
    first, tuned = tmp_path / "first", tmp_path / "tuned"
    main(["train-state", "--data", str(data), "--out", str(first), "--steps", "10", "--unroll", "4"])
    main(["train-state", "--data", str(data), "--extra-data", str(more), "--out", str(tuned), "--steps", "10",
          "--unroll", "4", "--init", str(first), "--no-last-action"])
    before, after = load_state_model(first).state_dict(), load_state_model(tuned).state_dict()
    statistics = [name for name in before if "mean" in name or "std" in name]
    assert statistics and all(torch.equal(before[name], after[name]) for name in statistics)  # kept, not refitted
    assert any(not torch.equal(before[name], after[name]) for name in before if name not in statistics)  # trained on
    assert load_state_model(tuned).config == load_state_model(first).config  # its architecture, not the flags'
    saved = json.loads((tuned / "config.json").read_text())["train"]
    assert saved["init"] == str(resolve_checkpoint(first))  # the checkpoint it started from, saved with the run
    other = write_robot_dataset(tmp_path / "other", episodes=4, steps=12, action_dim=5)
    with pytest.raises(SystemExit):
        main(["train-state", "--data", str(other), "--out", str(tmp_path / "bad"), "--steps", "2", "--init", str(first)])
    assert "its model takes" in capsys.readouterr().err
