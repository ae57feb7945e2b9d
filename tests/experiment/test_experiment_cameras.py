"""The experiment's `cameras`: one setting that every stage reads, and old experiments keep theirs."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from gymnast.experiment.config import EXPERIMENT_PRESETS, ExperimentConfig
from gymnast.experiment.pipeline import saved_experiment_config


def test_every_stage_is_told_the_experiments_cameras():
    config = dataclasses.replace(EXPERIMENT_PRESETS["debug"], cameras=("front", "gripper", "hand")).resolved()
    assert config.collect.env.cameras == config.sft.cameras == ("front", "gripper", "hand")
    assert config.world_model.cameras == config.judge.cameras == ("front", "gripper", "hand")
    # One front view is read as the stages read a dataset's first camera alone.
    alone = dataclasses.replace(EXPERIMENT_PRESETS["debug"], cameras=("front",)).resolved()
    assert alone.collect.env.cameras == ("front",)
    assert alone.sft.cameras == alone.world_model.cameras == alone.judge.cameras == ()


def test_the_presets_see_three_views_and_the_tests_two():
    assert {name: preset.cameras for name, preset in EXPERIMENT_PRESETS.items()} == {
        **{name: ("front", "gripper", "hand") for name in EXPERIMENT_PRESETS}, "debug": ("front", "gripper")}


@pytest.mark.parametrize("cameras", [("top",), ("front", "front"), ()])
def test_unknown_repeated_or_no_cameras_are_refused_at_once(cameras):
    with pytest.raises(ValueError, match="EnvConfig.cameras"):
        ExperimentConfig(cameras=cameras)


def test_an_experiment_saved_before_cameras_were_a_setting_resumes_with_the_front_view(tmp_path: Path):
    saved = json.loads(json.dumps(dataclasses.asdict(EXPERIMENT_PRESETS["debug"].resolved())))
    del saved["cameras"], saved["judge_rollouts"], saved["signal_weak_scenes"], saved["judge"]["hold_steps"]
    del saved["collect"]["env"]["cameras"]
    saved["signal_scenes"] = 3
    (tmp_path / "config.json").write_text(json.dumps(saved))
    config = saved_experiment_config(tmp_path).resolved()
    assert config.cameras == config.collect.env.cameras == ("front",)
    assert config.sft.cameras == config.world_model.cameras == config.judge.cameras == ()
    assert config.judge_rollouts == 0  # as it ran: its judge learned from no policy rollouts
    assert config.signal_weak_scenes == 3  # ... and its weak tasks took as many signal starts as the others
    assert config.judge.hold_steps == 1  # ... and its judge believed a single frame
