"""benchmarks/judge_hold.py: a judge measured again under other hold rules reproduces, under its own,
the figures its training reported."""

from __future__ import annotations

import dataclasses
import json

import pytest
from benchmark_scripts import benchmark_script

from gymnast.reward.judges.train import JUDGE_PRESETS, train_judge


def test_each_rule_chooses_its_threshold_and_the_judges_own_rule_gives_its_reported_figures(tiny_dataset, tmp_path):
    config = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25, validation_fraction=0.3, hold_steps=3)
    reported = train_judge(tiny_dataset, tmp_path / "judge", config, progress=False)
    result = benchmark_script("judge_hold").measure(tmp_path / "judge", [1, 3, 6])
    assert result["trained_hold_steps"] == 3 and [row["hold_steps"] for row in result["rows"]] == [1, 3, 6]
    own = result["rows"][1]
    assert own["threshold"] == pytest.approx(reported["validation_threshold"])
    assert (own["real_tpr"], own["real_fpr"]) == (reported["real_tpr"], reported["real_fpr"])
    assert own["real_auc"] == reported["real_roc"]["auc"]
    assert json.loads(json.dumps(result)) == result  # what --out writes


def test_a_judge_of_whole_videos_is_refused(tiny_dataset, tmp_path):
    config = dataclasses.replace(JUDGE_PRESETS["debug"], kind="video")
    train_judge(tiny_dataset, tmp_path / "video", config, progress=False)
    with pytest.raises(ValueError, match="not a per-frame judge"):
        benchmark_script("judge_hold").measure(tmp_path / "video", [1])


def test_an_earlier_checkpoint_is_measured_as_if_training_had_stopped_there(tiny_dataset, tmp_path):
    config = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25, validation_fraction=0.3, hold_steps=3)
    train_judge(tiny_dataset, tmp_path / "judge", config, progress=False)
    steps = sorted(int(path.name) for path in (tmp_path / "judge" / "checkpoints").glob("[0-9]*"))
    newest = benchmark_script("judge_hold").measure(tmp_path / "judge", [3])
    assert benchmark_script("judge_hold").measure(tmp_path / "judge", [3], checkpoint=steps[-1])["rows"] == newest["rows"]
    with pytest.raises(FileNotFoundError, match="999999"):
        benchmark_script("judge_hold").measure(tmp_path / "judge", [3], checkpoint=999999)
