"""The progress judge: targets from the dense reward, a video scored by its mean progress, soft-label
frame batches, and a trained judge that loads as a continuous reward."""

import dataclasses

import numpy as np
import pytest
import torch

from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.progress import ProgressJudge, progress_loss, progress_targets
from gymnast.reward.select import make_reward, measure_judge
from gymnast.reward.spec import RewardSpec
from gymnast.reward.judges.train import JUDGE_PRESETS, FramePool, load_judge, train_judge
from gymnast.reward.judges.videos import Video

DEBUG = dataclasses.replace(JUDGE_PRESETS["debug"], kind="progress", heldout_fraction=0.25, validation_fraction=0.2)


def test_targets_are_the_reward_that_led_to_each_frame_scaled_to_one():
    targets = progress_targets(np.array([0.0, 5.0, 10.0, 12.0]))
    assert targets.tolist() == [0.0, 0.0, 0.5, 1.0, 1.0]  # the start frame first; clipped at the maximum


def test_a_video_scores_the_mean_progress_of_its_frames_after_the_first():
    judge = ProgressJudge(JudgeConfig(width=16, image_size=16)).eval()
    videos = torch.randint(0, 255, (3, 6, 16, 16, 3), dtype=torch.uint8)
    per_frame = judge.frame_probabilities(videos, ["push the puck"] * 3)
    assert torch.allclose(judge.score(videos, ["push the puck"] * 3), per_frame[:, 1:].mean(dim=1))
    assert torch.allclose(judge.step_rewards(videos, ["push the puck"] * 3), per_frame[:, 1:])
    assert not judge.binary and judge.score(videos[:, :1], ["push the puck"] * 3).tolist() == [0.0] * 3


def test_progress_batches_carry_the_frames_progress_as_labels():
    shows = torch.tensor([False, False, False, True, True])
    frames = torch.arange(5, dtype=torch.uint8)[:, None, None, None].expand(-1, 8, 8, 3).contiguous()
    progress = torch.tensor([0.0, 0.2, 0.4, 1.0, 1.0])
    pool = FramePool([Video(frames, shows.cummax(0).values, shows, "reach", False, progress)], ambiguous=0,
                     progress=True)
    _, sampled, _, labels = pool.sample(8, torch.Generator().manual_seed(0))
    assert labels.dtype == torch.float32
    assert all(label == progress[int(f[0, 0, 0])] for f, label in zip(sampled, labels))  # each frame's own target


def test_the_loss_falls_as_the_prediction_nears_the_target():
    judge = ProgressJudge(JudgeConfig(width=16, image_size=16))
    frames = torch.zeros(2, 16, 16, 3, dtype=torch.uint8)
    text = torch.zeros(2, 384)
    losses = []
    for bias in (-5.0, 0.0):  # sigmoid -> about 0 and 0.5, against targets of 0.5
        with torch.no_grad():
            judge.head[-1].weight.zero_()
            judge.head[-1].bias.fill_(bias)
        loss, metrics = progress_loss(judge, frames, frames, text, torch.full((2,), 0.5))
        losses.append(loss.item())
    assert losses[1] < losses[0] and metrics["train/mae"] == pytest.approx(0.0, abs=1e-6)


def test_a_trained_progress_judge_reports_correlations_and_loads_as_a_continuous_reward(tiny_dataset, tmp_path):
    report = train_judge(tiny_dataset, tmp_path / "judge", DEBUG, progress=False)
    assert report["kind"] == "progress" and "validation_threshold" not in report
    assert {"real_frame_pearson", "real_frame_mae", "real_video_pearson"} <= set(report)
    judge = make_reward(RewardSpec.judge(tmp_path / "judge"))
    assert isinstance(judge, ProgressJudge) and not judge.binary
    assert load_judge(tmp_path / "judge").backend == "progress-judge"
    # eval-judge measures it as train-judge did: correlations, not a threshold's TPR/FPR
    measured = measure_judge(RewardSpec.judge(tmp_path / "judge"), tiny_dataset, tmp_path / "eval.json",
                             heldout_fraction=DEBUG.heldout_fraction)
    assert measured["real_frame_pearson"] == report["real_frame_pearson"] and "real_tpr" not in measured
