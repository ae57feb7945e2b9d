"""World-model training: the held-out split, clip sampling, resume, and the CLI end to end."""

import dataclasses
import json

import pytest
import torch
from resumed_runs import assert_resumed_as_whole, stop_after

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import EpisodeInfo
from gymnast.envs.tasks import eval_seed
from gymnast.utils.metrics import read_metrics
from gymnast.world_model.controllability import ControllabilityConfig
from gymnast.world_model.data import EpisodeBank, split_episodes
from gymnast.world_model.evaluate import WorldModelEvalConfig, evaluate_world_model
from gymnast.world_model.train import WM_PRESETS, future_at, train_world_model

# The tiny dataset's scenes are reach and drawer-close, seeds 0 and 1; at 0.25, drawer-close/0 is held out.
DEBUG = dataclasses.replace(WM_PRESETS["debug"], heldout_fraction=0.25)


def info(task: str, seed: int, behaviour: str = "expert") -> EpisodeInfo:
    return EpisodeInfo(task=task, instruction="x", success=True, behaviour=behaviour, noise=0.0, seed=seed)


def test_split_keeps_scenes_together_and_never_uses_evaluation_seeds():
    infos = [info(t, s, b) for t in ("reach-v3", "push-v3") for s in range(40) for b in ("expert", "random")]
    infos.append(info("reach-v3", eval_seed(0)))
    train, heldout = split_episodes(infos, 0.25)
    assert len(infos) - 1 not in train + heldout
    scenes = lambda ids: {(infos[i].task, infos[i].seed) for i in ids}  # noqa: E731
    assert not scenes(train) & scenes(heldout)
    assert 0.1 < len(heldout) / len(train + heldout) < 0.4
    assert split_episodes(infos, 0.25) == (train, heldout)


def test_clips_before_the_episode_start_show_a_robot_standing_still(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    bank = EpisodeBank(dataset, [0])
    episode = dataset.load(0)
    clip = bank.clip(0, start=-1, context=2, future=3)
    assert torch.equal(clip.context[0, 0], torch.from_numpy(episode.frames[0]))
    assert torch.equal(clip.context[0, 1], torch.from_numpy(episode.frames[0]))
    assert torch.equal(clip.future[0], torch.from_numpy(episode.frames[1:4]))
    assert torch.equal(clip.actions[0], torch.from_numpy(episode.actions[:3]).float())
    with pytest.raises(IndexError, match="outside episode"):
        bank.clip(0, start=-2, context=2, future=3)


def test_sampled_clips_pair_each_future_frame_with_the_action_before_it(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    bank = EpisodeBank(dataset, range(len(dataset.lengths)))
    clips = bank.sample(6, context=2, future=4, generator=torch.Generator().manual_seed(0))
    assert clips.context.shape == (6, 2, 32, 32, 3) and clips.future.shape == (6, 4, 32, 32, 3)
    assert clips.actions.shape == (6, 4, 4)


def test_training_lowers_the_imagination_error(tiny_dataset, tmp_path):
    config = dataclasses.replace(DEBUG, steps=60, lr=3e-3, log_every=1, validate_every=60, video_every=60, checkpoint_every=60)
    train_world_model(tiny_dataset, tmp_path, config, progress=False)
    losses = [line["train/loss"] for line in read_metrics(tmp_path)]
    assert sum(losses[-10:]) < 0.7 * sum(losses[:10])


def test_resume_from_a_checkpoint_continues_exactly(tiny_dataset, tmp_path):
    whole, interrupted = tmp_path / "whole", tmp_path / "interrupted"
    train_world_model(tiny_dataset, whole, DEBUG, progress=False)
    # A run that stopped after its step-2 checkpoint, with one metrics line logged past it.
    stop_after(whole, interrupted, step=2, metric_lines=3)
    train_world_model(tiny_dataset, interrupted, DEBUG, resume=True, progress=False)
    assert_resumed_as_whole(whole, interrupted, final_step=4)


def test_eval_reports_every_horizon_the_baseline_and_controllability(tiny_dataset, tmp_path):
    train_world_model(tiny_dataset, tmp_path / "wm", DEBUG, progress=False)
    config = WorldModelEvalConfig(videos=1, controllability=ControllabilityConfig(scenes=1, sequences=3, horizon=8))
    report = evaluate_world_model(tmp_path / "wm", tiny_dataset, tmp_path / "eval.json", config, progress=False)
    for key in ("psnr_h1", "psnr_h8", "psnr_h32", "ssim_h32", "psnr_full", "moving_psnr_h32", "copy_last_psnr_h32",
                "copy_last_moving_psnr_h32", "perceptual_h1"):
        assert key in report
    assert report["per_task"].keys() == {"drawer-close-v3"}
    control = report["controllability"]
    assert control["scenes"] == 1 and control["start_frame_psnr"] > 40  # the simulator restarts the recorded scene
    assert json.loads((tmp_path / "eval.json").read_text())["psnr_h1"] == report["psnr_h1"]
    assert len(list((tmp_path / "eval_videos").glob("*.mp4"))) == 1


def test_cli_train_wm_then_eval_wm(tiny_dataset, tmp_path, capsys):
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(tmp_path / "wm"), "--preset", "debug"])
    assert "world model:" in capsys.readouterr().out
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(tmp_path / "wm"), "--resume"])
    main(["train-wm", "--out", str(tmp_path / "wm"), "--resume"])  # the data comes from the run
    with pytest.raises(SystemExit):
        main(["train-wm", "--out", str(tmp_path / "wm"), "--resume", "--steps", "99"])
    assert "--steps 99 disagrees with the run" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["eval-wm", "--wm", str(tmp_path / "missing"), "--data", str(tiny_dataset), "--out", str(tmp_path / "e.json")])
    assert "no checkpoint" in capsys.readouterr().err


def test_clip_length_grows_from_four_frames_to_the_full_horizon():
    config = dataclasses.replace(WM_PRESETS["full"], steps=100, future=32, warmup_future=0.5)
    lengths = [future_at(step, config) for step in range(100)]
    assert lengths[0] == 4 and lengths[49] < 32 and lengths[50:] == [32] * 50
    assert lengths == sorted(lengths)
    # Clips shorter than four frames (one-step training, --future 1) are that short from the start.
    one_step = dataclasses.replace(config, future=1)
    assert {future_at(step, one_step) for step in range(100)} == {1}
