"""Judges of several cameras: each view is encoded alone, train-judge and eval-judge read the
cameras the judge was trained on, and what cannot see several cameras says so."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import torch

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.envs.tasks import eval_seed
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.video import LearnedJudge
from gymnast.reward.judges.train import load_judge
from gymnast.reward.judges.videos import heldout_videos

WORLD_MODEL = Path(__file__).resolve().parents[2] / "results" / "world_model" / "wm"

TWO = ("front", "gripper")


def test_each_camera_is_judged_by_the_same_encoder_alone():
    judge = FrameJudge(JudgeConfig(width=16, image_size=16, cameras=TWO)).eval()
    first = torch.randint(0, 256, (3, 16, 32, 3), dtype=torch.uint8)
    frames = torch.randint(0, 256, (3, 16, 32, 3), dtype=torch.uint8)
    text = torch.zeros(3, 384)
    with torch.no_grad():
        logits = judge(first, frames, text)
        pair = torch.cat([first[..., :16, :], frames[..., :16, :]], dim=-1).permute(0, 3, 1, 2).float() / 255 * 2 - 1
        front = judge.vision(pair)  # the front view's features, encoded alone
        gripper_pair = torch.cat([first[..., 16:, :], frames[..., 16:, :]], dim=-1).permute(0, 3, 1, 2).float() / 255 * 2 - 1
        both = torch.cat([front, judge.vision(gripper_pair), judge.text(text)], dim=1)
        torch.testing.assert_close(logits, judge.head(both).squeeze(1), atol=2e-2, rtol=0)  # bf16 convolutions
    with pytest.raises(ValueError, match=r"cameras front,gripper needs \(N, 16, 32, 3\) frames"):
        judge(first[..., :16, :], frames[..., :16, :], text)
    with pytest.raises(ValueError, match="the video judge sees one camera"):
        LearnedJudge(JudgeConfig(width=16, image_size=16, cameras=TWO))


def test_train_judge_on_two_cameras_then_eval_judge_reads_them_again(two_camera_demos, tmp_path, capsys):
    run = tmp_path / "judge"
    main(["train-judge", "--data", str(two_camera_demos), "--out", str(run), "--preset", "debug", "--cameras",
          "front,gripper"])
    judge = load_judge(run)
    assert judge.config.cameras == TWO and judge.config.image_size == 32
    report = tmp_path / "eval_judge.json"
    main(["eval-judge", "--reward", f"judge:{run}", "--data", str(two_camera_demos), "--out", str(report),
          "--heldout-fraction", "0.9"])  # the four scenes' hashes are below 0.8
    measured = json.loads(report.read_text())
    assert measured["camera"] == "front,gripper" and measured["real_positives"] + measured["real_negatives"] > 0
    with pytest.raises(SystemExit):
        main(["train-judge", "--data", str(two_camera_demos), "--out", str(tmp_path / "with_wm"), "--preset", "debug",
              "--cameras", "front,gripper", "--wm", str(WORLD_MODEL)])
    assert "but the world model" in (err := capsys.readouterr().err) and "imagines one camera" in err


def test_a_held_out_fraction_of_one_judges_every_episode_of_new_scenes(two_camera_demos):
    dataset = EpisodeDataset(two_camera_demos, cameras=TWO)
    every = heldout_videos(dataset, 1.0)
    assert [video.instruction for video in every] == [info.instruction for info in dataset.episodes]
    assert heldout_videos(dataset, 0.0) == []


def test_a_held_out_fraction_of_one_still_leaves_out_episodes_of_evaluation_seeds(two_camera_demos):
    dataset = EpisodeDataset(two_camera_demos, cameras=TWO)
    dataset.episodes[0] = dataclasses.replace(dataset.episodes[0], seed=eval_seed(0))  # recorded elsewhere
    every = heldout_videos(dataset, 1.0)
    assert len(every) == len(dataset.episodes) - 1
