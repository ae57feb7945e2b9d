"""Calibrating a trained per-frame judge on labelled real episodes it never saw: the operating point
held to a false-success rate, the options it chooses among, and the judge run it writes."""

import dataclasses

import pytest
import torch

from gymnast.data.collect import CollectConfig, collect
from gymnast.config import EnvConfig
from gymnast.reward.judges.calibrate import CalibrationConfig, calibrate_judge
from gymnast.reward.judges.frames import FrameJudge, held_probability
from gymnast.reward.judges.measure import evaluate_judge, threshold_at_fpr
from gymnast.reward.judges.train import JUDGE_PRESETS, load_judge, run_scene_videos, train_judge
from gymnast.utils.atomic import read_json

DEBUG = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25, validation_fraction=0.3, hold_steps=3,
                            checkpoint_every=3)


@pytest.fixture(scope="module")
def judge_run(tiny_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("calibrated") / "judge"
    train_judge(tiny_dataset, out, DEBUG, progress=False)
    return out


@pytest.fixture(scope="module")
def calibration_data(tmp_path_factory):
    """New scenes of the judge's tasks, recorded as its data was (experts and failures, 32 px)."""
    out = tmp_path_factory.mktemp("calibration_data")
    collect(CollectConfig(tasks="reach-v3,drawer-close-v3", episodes_per_task=2, noise=(0.0,), failure_fraction=0.5,
                          first_seed=500, workers=1, env=EnvConfig(image_size=32, horizon=100)), out, progress=False)
    return out


def test_the_threshold_passes_the_most_successes_within_the_false_success_rate():
    scores = torch.tensor([0.9, 0.8, 0.7, 0.6, 0.95, 0.5, 0.4, 0.3], dtype=torch.float64)
    truth = torch.tensor([True, True, True, True, False, False, False, False])
    one_failure = threshold_at_fpr(scores, truth, max_fpr=0.25)  # one of four failures may pass
    assert (one_failure["tpr"], one_failure["fpr"]) == (1.0, 0.25) and 0.5 < one_failure["threshold"] <= 0.6
    none = threshold_at_fpr(scores, truth, max_fpr=0.0)  # a failure outscores every success: nothing passes
    assert (none["tpr"], none["fpr"]) == (0.0, 0.0) and none["threshold"] > 0.95


def test_the_calibrated_judge_is_a_run_measured_on_the_held_out_scenes(judge_run, calibration_data, tmp_path):
    config = CalibrationConfig(max_fpr=0.5, hold_steps=(1, 3), checkpoints=(3,))
    report = calibrate_judge(judge_run, [calibration_data], tmp_path / "calibrated", config, progress=False)
    written = read_json(tmp_path / "calibrated" / "calibration.json")
    assert [(o["checkpoint"], o["hold_steps"]) for o in written["options"]] == [(3, 1), (3, 3), (DEBUG.steps, 1), (DEBUG.steps, 3)]
    best = max(option["tpr"] for option in written["options"])
    assert written["chosen"]["tpr"] == best and written["chosen"]["fpr"] <= 0.5
    judge = load_judge(tmp_path / "calibrated")
    assert judge.config.threshold == written["chosen"]["threshold"]
    assert judge.config.hold_steps == written["chosen"]["hold_steps"]
    again = evaluate_judge(judge, run_scene_videos(judge_run, 2))
    assert {key: report[key] for key in again} == again
    assert report["calibration_checkpoint"] == written["chosen"]["checkpoint"]
    assert read_json(tmp_path / "calibrated" / "metrics.json") == report


def test_a_case_cut_from_a_video_reads_the_first_frames_judged_with_the_whole_video(judge_run, calibration_data):
    from gymnast.reward.judges.calibrate import calibration_cases, case_frame_probabilities

    judge = load_judge(judge_run)
    cases, truth = calibration_cases(judge_run, [calibration_data], progress=False)
    assert len(cases) > len({id(video) for video, _ in cases})  # successes are cut short too
    shortcut = case_frame_probabilities(judge, cases)
    for (video, length), probabilities in zip(cases, shortcut):
        alone = judge.frame_probabilities(video.frames[None, :length], [video.instruction])[0]
        assert torch.allclose(probabilities, alone, atol=1e-3)
        assert torch.allclose(held_probability(probabilities[None], 3), held_probability(alone[None], 3), atol=1e-3)


def test_what_cannot_be_calibrated_is_named(judge_run, calibration_data, tiny_dataset, tmp_path):
    with pytest.raises(FileNotFoundError, match="000099"):
        calibrate_judge(judge_run, [calibration_data], tmp_path / "a", CalibrationConfig(checkpoints=(99,)), progress=False)
    video_judge = tmp_path / "video"
    train_judge(tiny_dataset, video_judge, dataclasses.replace(DEBUG, kind="video"), progress=False)
    with pytest.raises(ValueError, match="not a per-frame judge"):
        calibrate_judge(video_judge, [calibration_data], tmp_path / "b", progress=False)
    with pytest.raises(ValueError, match="max_fpr"):
        CalibrationConfig(max_fpr=1.0)
    with pytest.raises(ValueError, match="not a calibrated judge"):
        calibrate_judge(judge_run, [calibration_data], judge_run, progress=False)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    assert isinstance(load_judge(judge_run), FrameJudge)


def test_the_checkpoint_mean_benchmark_of_one_checkpoint_is_the_calibration(judge_run, calibration_data, tmp_path):
    from benchmark_scripts import benchmark_script

    config = CalibrationConfig(max_fpr=0.5, hold_steps=(1, 3))
    report = calibrate_judge(judge_run, [calibration_data], tmp_path / "calibrated", config, progress=False)
    result = benchmark_script("judge_checkpoint_mean").measure(judge_run, [calibration_data], [3, DEBUG.steps],
                                                              holds=[1, 3], max_fpr=[0.5])
    assert [row["checkpoints"] for row in result["rows"]] == [[3], [DEBUG.steps], [3, DEBUG.steps]]
    newest = result["rows"][1]
    assert (newest["hold_steps"], newest["calibration_tpr"], newest["calibration_fpr"]) == (
        report["calibration_hold_steps"], report["calibration_tpr"], report["calibration_fpr"])
    assert newest["threshold"] == pytest.approx(report["calibration_threshold"])
    assert (newest["heldout_tpr"], newest["heldout_fpr"]) == (report["real_tpr"], report["real_fpr"])
    assert result["heldout_cases"] == report["real_positives"] + report["real_negatives"]
