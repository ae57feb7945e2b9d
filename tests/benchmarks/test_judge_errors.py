"""benchmarks/judge_errors.py: the cases it lists are the held-out errors the judge's training counted."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
from benchmark_scripts import benchmark_script

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


def test_the_closest_approach_is_the_distance_the_task_succeeds_by():
    script = benchmark_script("judge_errors")
    states = np.zeros((3, 39))
    states[:, 36:39] = [0.0, 0.8, 0.1]  # the goal
    states[:, 0:3] = [[0.0, 0.6, 0.1], [0.0, 0.74, 0.1], [0.0, 0.7, 0.1]]  # the hand: 20, 6 and 10 cm away
    states[:, 4:7] = [0.0, 0.8, 0.2]  # the object: 10 cm above the goal
    assert script.closest_approach("reach-v3", states) == {"closest_cm": 6.0, "success_radius_cm": 5.0}
    assert script.closest_approach("pick-place-v3", states) == {"closest_cm": 10.0, "success_radius_cm": 7.0}
    assert script.closest_approach("door-open-v3", states) is None  # not one distance to the goal
    assert script.closest_approach("reach-v3", states[:, :4]) is None  # a dataset that records no goal
