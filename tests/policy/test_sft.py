"""Behaviour cloning: demo selection, augmentation, learning, checkpoints and exact resume."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch
from resumed_runs import assert_resumed_as_whole, stop_after

from gymnast.data.lerobot import EpisodeDataset
from gymnast.policy.sft import SFT_PRESETS, SFTConfig, load_demos, random_shift, select_demos, train_sft
from gymnast.policy.load import load_policy
from gymnast.policy.vla import VLAConfig
from gymnast.utils.metrics import read_metrics

TINY = dataclasses.replace(SFT_PRESETS["debug"], demos_per_task=2, vla=VLAConfig(width=32, layers=1, heads=2, image_size=32))


def test_only_successful_expert_episodes_are_imitated(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    chosen = select_demos(dataset, per_task=2)
    assert len(chosen) == 4
    assert all(dataset.episodes[i].success and dataset.episodes[i].behaviour == "expert" for i in chosen)
    with pytest.raises(ValueError, match="reach-v3.*2 successful.*asks for 3"):
        select_demos(dataset, per_task=3, tasks="reach-v3")


def test_action_chunks_past_the_episode_end_are_masked(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    index = select_demos(dataset, 1, "reach-v3")[0]
    demos = load_demos(dataset, [index], chunk_size=5)
    episode = dataset.load(index)
    assert len(demos.images) == episode.length
    torch.testing.assert_close(demos.chunks[0], torch.from_numpy(episode.actions[:5]))
    assert demos.valid[-1].tolist() == [True, False, False, False, False]


def test_random_shift_moves_content_without_changing_shape():
    images = torch.zeros(8, 16, 16, 3, dtype=torch.uint8)
    images[:, 8, 8] = 255
    shifted = random_shift(images, 2, torch.Generator().manual_seed(0))
    assert shifted.shape == images.shape and shifted.dtype == torch.uint8
    assert (shifted.flatten(1).amax(1) == 255).all()  # the bright pixel is still in every image
    assert torch.equal(random_shift(images, 0, torch.Generator()), images)


@pytest.mark.parametrize("family", ["tokens", "flow"])
def test_sft_drives_the_loss_down(family, tiny_dataset, tmp_path):
    # 40 steps end at about 0.65 (tokens) and 0.5 (flow) of the first loss
    config = dataclasses.replace(TINY, policy=family, steps=40, batch_size=16, lr=2e-3, warmup_steps=5, log_every=1, checkpoint_every=40)
    train_sft(tiny_dataset, tmp_path, config, progress=False)
    losses = [row["train/loss"] for row in read_metrics(tmp_path)]
    assert sum(losses[-10:]) / 10 < 0.75 * losses[0], losses
    policy = load_policy(tmp_path)
    assert policy.config.image_size == 32 and {"tokens": "vla", "flow": "flow_vla"}[family] in policy.spec()


@pytest.mark.parametrize("family", ["tokens", "flow"])
def test_resume_from_a_checkpoint_continues_exactly(family, tiny_dataset, tmp_path):
    config = dataclasses.replace(TINY, policy=family, steps=6, checkpoint_every=3, log_every=1)
    whole = tmp_path / "whole"
    train_sft(tiny_dataset, whole, config, progress=False)
    interrupted = tmp_path / "interrupted"
    stop_after(whole, interrupted, step=3, metric_lines=4)
    train_sft(tiny_dataset, interrupted, config, resume=True, progress=False)
    assert_resumed_as_whole(whole, interrupted, final_step=6)


def test_presets_are_valid_configs():
    assert set(SFT_PRESETS) == {"debug", "demo", "full"}
    assert all(isinstance(c, SFTConfig) for c in SFT_PRESETS.values())


def test_cli_sft_then_eval_runs_end_to_end(tiny_dataset, tmp_path, capsys):
    from gymnast.cli import main

    run = tmp_path / "run"
    main(["sft", "--data", str(tiny_dataset), "--out", str(run), "--preset", "debug", "--demos-per-task", "2"])
    assert (run / "checkpoints" / "last").read_text() == "000006"
    main(["sft", "--data", str(tiny_dataset), "--out", str(run), "--resume"])  # already finished: no new steps
    main(["sft", "--out", str(run), "--resume"])  # the data comes from the run
    assert sorted(p.name for p in (run / "checkpoints").iterdir() if p.name != "last") == ["000003", "000006"]
    report = tmp_path / "eval.json"
    main(["eval", "--policy", str(run), "--tasks", "reach-v3", "--episodes", "2", "--workers", "1",
          "--env.image-size", "32", "--env.horizon", "20", "--out", str(report)])
    assert json.loads(report.read_text())["episodes"] == 2
    assert "reach-v3" in capsys.readouterr().out


def test_cli_sft_trains_a_flow_policy_that_eval_reads(tiny_dataset, tmp_path, capsys):
    from gymnast.cli import main

    run = tmp_path / "flow"
    main(["sft", "--data", str(tiny_dataset), "--out", str(run), "--preset", "debug", "--policy-type", "flow"])
    assert json.loads((run / "config.json").read_text())["sft"]["policy"] == "flow"
    main(["sft", "--out", str(run), "--resume"])  # the family comes from the run
    report = tmp_path / "eval.json"
    main(["eval", "--policy", str(run), "--tasks", "reach-v3", "--episodes", "1", "--workers", "1",
          "--env.image-size", "32", "--env.horizon", "10", "--out", str(report)])
    assert json.loads(report.read_text())["episodes"] == 1
