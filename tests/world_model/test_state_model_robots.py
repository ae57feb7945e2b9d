"""How a state model is measured: over the whole state for another robot (its states have their own
layout), and also at the hand and the object for Meta-World's."""

from __future__ import annotations

import json

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
