"""SFT on imagined sight: the demonstrations as a world model draws them under their own actions,
paired with the same next actions, beside the real frames."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.policy.sft import load_demos, select_demos
from gymnast.world_model.base import load_world_model, rollout
from gymnast.world_model.reimagine import imagined_demos
from gymnast.world_model.train import WM_PRESETS, train_world_model

CHUNK = 5


@pytest.fixture(scope="module")
def world_model(tiny_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("wm")
    train_world_model(tiny_dataset, out, dataclasses.replace(WM_PRESETS["debug"], heldout_fraction=0.25), progress=False)
    return out


def test_each_imagined_frame_a_policy_reads_is_paired_with_the_actions_the_real_one_was(tiny_dataset, world_model):
    dataset = EpisodeDataset(tiny_dataset)
    chosen = select_demos(dataset, per_task=1)
    demos = load_demos(dataset, chosen, CHUNK)
    imagined = imagined_demos(dataset, chosen, demos, CHUNK, world_model)

    lengths = [dataset.load(i).length for i in chosen]
    read = torch.cat([torch.arange(length) % CHUNK == 0 for length in lengths])
    assert len(imagined.images) == sum(-(-length // CHUNK) for length in lengths) == int(read.sum())
    torch.testing.assert_close(imagined.chunks, demos.chunks[read])
    assert torch.equal(imagined.valid, demos.valid[read]) and torch.equal(imagined.instruction, demos.instruction[read])
    # An episode's first sample is its real first frame; the later ones are the world model's
    # drawing after the episode's own actions, the same as imagining the episode directly.
    episode = dataset.load(chosen[0])
    first = torch.from_numpy(episode.observed_frames[:1])
    assert torch.equal(imagined.images[0], first[0])
    expected = rollout(load_world_model(world_model), first[None], torch.from_numpy(episode.actions)[None].float()).frames[0]
    assert torch.equal(imagined.images[1], expected[CHUNK - 1])
    assert not torch.equal(imagined.images[1], demos.images[CHUNK])  # a drawing, not the camera's frame


def test_sft_fine_tunes_a_policy_on_imagined_sight_and_saves_the_world_model_it_read(tiny_dataset, world_model,
                                                                                        tmp_path, capsys):
    main(["sft", "--data", str(tiny_dataset), "--out", str(tmp_path / "sft"), "--preset", "debug"])
    main(["sft", "--data", str(tiny_dataset), "--out", str(tmp_path / "tuned"), "--preset", "debug",
          "--init", str(tmp_path / "sft"), "--imagined-by", str(world_model)])
    saved = json.loads((tmp_path / "tuned" / "config.json").read_text())
    dataset = EpisodeDataset(tiny_dataset)
    frames_read = sum(-(-dataset.load(i).length // CHUNK) for i in select_demos(dataset, per_task=1))
    assert saved["imagined_by"] == str(world_model) and saved["init"] == str(tmp_path / "sft")
    assert saved["extra_samples"] == frames_read
    capsys.readouterr()
    with pytest.raises(SystemExit):  # a resumed run keeps the world model it started with
        main(["sft", "--out", str(tmp_path / "tuned"), "--resume", "--imagined-by", str(tmp_path / "sft")])
    assert "--imagined-by" in capsys.readouterr().err


def test_a_world_model_that_draws_another_image_size_than_the_policy_reads_is_named(tiny_dataset, world_model):
    dataset = EpisodeDataset(tiny_dataset).fitted(16, "resize")  # the world model draws 32 px
    chosen = select_demos(dataset, per_task=1)
    with pytest.raises(ValueError, match="draws 32 px frames, but the policy reads 16 px"):
        imagined_demos(dataset, chosen, load_demos(dataset, chosen, CHUNK), CHUNK, world_model)
