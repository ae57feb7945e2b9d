"""benchmarks/judge_errors.py: the cases it lists are the held-out errors the judge's training counted."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from benchmark_scripts import benchmark_script

from gymnast.data.lerobot import EpisodeDataset
from gymnast.reward.judges.train import JUDGE_PRESETS, train_judge


def test_the_errors_listed_are_the_ones_the_training_metrics_counted(tiny_dataset, tmp_path):
    config = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25, validation_fraction=0.3, hold_steps=3)
    reported = train_judge(tiny_dataset, tmp_path / "judge", config, progress=False)
    result = benchmark_script("judge_errors").judge_errors(tmp_path / "judge")
    assert (result["positives"], result["negatives"]) == (reported["real_positives"], reported["real_negatives"])
    assert result["missed_successes"] == round((1 - reported["real_tpr"]) * reported["real_positives"])
    assert result["false_successes"] == round(reported["real_fpr"] * reported["real_negatives"])
    assert len(result["errors"]) == result["missed_successes"] + result["false_successes"]
    threshold = result["threshold"]
    assert all((error["probability"] >= threshold) != error["success"] for error in result["errors"])
    assert json.loads(json.dumps(result)) == result  # what --out writes


def test_the_closest_approach_is_the_distance_meta_world_measures_success_by(tiny_dataset):
    script = benchmark_script("judge_errors")
    dataset = EpisodeDataset(tiny_dataset)
    reaches = [dataset.columns(i) for i, info in enumerate(dataset.episodes) if info.task == "reach-v3"]
    assert {episode.info.success for episode in reaches} == {True, False}
    for episode in reaches:
        near = script.closest_approach(episode, len(episode.full_states))
        assert near["success_radius_cm"] == 5.0 and (near["closest_cm"] <= 5.0) == episode.info.success
        # The tool centre between the finger pads, not the end effector the observation records.
        end_effector = np.linalg.norm(episode.full_states[:, 0:3] - episode.full_states[:, 36:39], axis=1).min()
        assert abs(100 * end_effector - near["closest_cm"]) > 1.0
        if episode.info.success:  # the start frame alone is farther
            assert script.closest_approach(episode, 1)["closest_cm"] > near["closest_cm"]
    drawer = next(i for i, info in enumerate(dataset.episodes) if info.task == "drawer-close-v3")
    assert script.closest_approach(dataset.columns(drawer), 10) is None  # not one distance to the goal


def test_an_episode_whose_replay_departs_from_its_recording_is_refused(tiny_dataset):
    script = benchmark_script("judge_errors")
    dataset = EpisodeDataset(tiny_dataset)
    reach = dataset.columns(next(i for i, info in enumerate(dataset.episodes) if info.task == "reach-v3"))
    pushed = dataclasses.replace(reach, actions=reach.actions + np.float32(0.5))
    with pytest.raises(ValueError, match=r"reach-v3 seed \d+ departs from its recording at step 1"):
        script.tool_centre_path(pushed)
    elsewhere = dataclasses.replace(reach, info=dataclasses.replace(reach.info, env_variant="sim-gap-mild"))
    with pytest.raises(ValueError, match="was recorded in 'sim-gap-mild'"):
        script.tool_centre_path(elsewhere)
