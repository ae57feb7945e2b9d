"""World-model training levers: moving-pixel weighting, fine-tuning from a run, training on several datasets."""

import dataclasses
import json
import shutil

import pytest
import torch
from safetensors.torch import load_file

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.world_model.base import load_world_model
from gymnast.world_model.train import WM_PRESETS, build_model, frame_loss, load_banks, saved_train_config, train_world_model

# The tiny dataset's scenes are reach and drawer-close, seeds 0 and 1; at 0.25, drawer-close/0 is held out.
DEBUG = dataclasses.replace(WM_PRESETS["debug"], heldout_fraction=0.25)
DEBUG32 = dataclasses.replace(DEBUG, model=dataclasses.replace(DEBUG.model, image_size=32))
HELDOUT_SCENE = ("drawer-close-v3", 0)


def clip(moving: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """A (1, 1, 3, 4, 4) target frame and its reference: black, with pixel (0, 0) lit if it `moving`."""
    reference = torch.zeros(1, 1, 3, 4, 4)
    target = reference.clone()
    if moving:
        target[..., 0, 0] = 1.0
    return target, reference


def test_without_moving_weight_the_loss_is_the_plain_mean_squared_error():
    target, reference = clip()
    imagined = torch.rand(1, 1, 3, 4, 4, generator=torch.Generator().manual_seed(0))
    loss, metrics = frame_loss(imagined, target, reference)
    assert loss.item() == (imagined - target).square().mean().item()
    assert metrics["train/loss"] == pytest.approx(loss.item())


def test_moving_weight_counts_the_moving_pixels_more_and_normalises():
    target, reference = clip()  # one moving pixel of 16
    on_mover = target.clone()
    on_mover[..., 0, 0] = 0.5  # error 0.25 on the moving pixel only
    on_static = target.clone()
    on_static[..., 1, 1] = 0.5  # error 0.25 on one static pixel only
    plain = frame_loss(on_mover, target, reference)[0].item()
    assert plain == pytest.approx(0.25 / 16)
    # Weights: 1 + 3 on the mover, 1 on the 15 others; the loss is sum(w e) / sum(w).
    assert frame_loss(on_mover, target, reference, moving_weight=3.0)[0].item() == pytest.approx(4 * 0.25 / 19)
    assert frame_loss(on_static, target, reference, moving_weight=3.0)[0].item() == pytest.approx(0.25 / 19)
    # The logged PSNR stays that of the unweighted error, whatever the weight.
    assert frame_loss(on_mover, target, reference, 3.0)[1]["train/psnr"] == frame_loss(on_mover, target, reference)[1]["train/psnr"]


def test_moving_weight_changes_nothing_where_nothing_moves():
    target, reference = clip(moving=False)
    imagined = torch.rand(2, 1, 3, 4, 4, generator=torch.Generator().manual_seed(1))
    target, reference = target.expand(2, -1, -1, -1, -1), reference.expand(2, -1, -1, -1, -1)
    assert frame_loss(imagined, target, reference, 10.0)[0].item() == pytest.approx(frame_loss(imagined, target, reference)[0].item())


def test_moving_weight_is_differentiable_and_weighs_the_gradient_towards_movers():
    target, reference = clip()
    imagined = torch.full((1, 1, 3, 4, 4), 0.5, requires_grad=True)
    frame_loss(imagined, target, reference, 3.0)[0].backward()
    grad = imagined.grad[0, 0, 0].abs()
    assert grad[0, 0] == pytest.approx(4 * grad[1, 1].item())


def test_init_starts_from_the_source_weights_and_refuses_another_spec(tiny_dataset, tmp_path):
    source = tmp_path / "source"
    train_world_model(tiny_dataset, source, DEBUG, progress=False)
    model = build_model(dataclasses.replace(DEBUG32, init=source, seed=7))
    saved = load_file(source / "checkpoints" / "000004" / "model.safetensors")
    for name, tensor in model.state_dict().items():
        torch.testing.assert_close(tensor, saved[name], rtol=0, atol=0, msg=name)
    # A fine-tuning run may change what does not change the weights.
    build_model(dataclasses.replace(DEBUG32, init=source, model=dataclasses.replace(DEBUG32.model, reanchor_every=8)))
    wider = dataclasses.replace(DEBUG32, init=source, model=dataclasses.replace(DEBUG32.model, latent_channels=8, blocks=2))
    with pytest.raises(ValueError, match=r"differs from this run's in blocks \(1 there, 2 here\), latent_channels"):
        build_model(wider)
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        build_model(dataclasses.replace(DEBUG32, init=tmp_path / "missing"))


def test_extra_data_grows_the_training_set_and_keeps_heldout_scenes_out(tiny_dataset, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(tiny_dataset, copy)
    one, one_heldout, _ = load_banks([EpisodeDataset(tiny_dataset)], 0.25)
    both, heldout, counts = load_banks([EpisodeDataset(tiny_dataset), EpisodeDataset(copy)], 0.25)
    assert len(both) == 2 * len(one) and len(heldout) == 2 * len(one_heldout)
    assert [c["train_episodes"] for c in counts] == [len(one), len(one)] and counts[1]["data"] == str(copy)
    assert set(both.roots) == {tiny_dataset, copy}
    assert HELDOUT_SCENE not in {(i.task, i.seed) for i in both.infos}
    assert {(i.task, i.seed) for i in heldout.infos} == {HELDOUT_SCENE}


def test_datasets_of_another_image_size_are_refused_by_name(tiny_dataset, tmp_path):
    small = tmp_path / "small"
    shutil.copytree(tiny_dataset, small)
    info = json.loads((small / "meta" / "info.json").read_text())
    key = next(k for k, f in info["features"].items() if f.get("dtype") in ("video", "image"))
    info["features"][key]["shape"] = [16, 16, 3]
    (small / "meta" / "info.json").write_text(json.dumps(info))
    with pytest.raises(ValueError, match=rf"{small}: frames are 16x16, but {tiny_dataset} has 32x32"):
        train_world_model(tiny_dataset, tmp_path / "wm", dataclasses.replace(DEBUG, extra_data=(small,)), progress=False)


def test_cli_fine_tunes_on_several_datasets_with_moving_weight(tiny_dataset, tmp_path, capsys):
    copy = tmp_path / "copy"
    shutil.copytree(tiny_dataset, copy)
    train_world_model(tiny_dataset, tmp_path / "source", DEBUG, progress=False)
    out = tmp_path / "tuned"
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(out), "--preset", "debug", "--moving-weight", "4",
          "--init", str(tmp_path / "source"), "--extra-data", str(copy), "--action-dropout", "0.2"])
    assert "world model:" in capsys.readouterr().out
    saved = json.loads((out / "config.json").read_text())
    assert saved["train"]["moving_weight"] == 4.0 and saved["train"]["extra_data"] == [str(copy)]
    # The source had no action dropout: its weights start the run, the "no action" embedding starts fresh.
    assert saved["model"]["action_dropout"] == 0.2 and saved["model"]["guidance"] == 1.0
    tuned = load_world_model(out, guidance=2.0)
    assert tuned.config.guidance == 2.0 and tuned.no_action is not None
    assert saved["train"]["init"] == str(tmp_path / "source" / "checkpoints" / "000004")  # the checkpoint it resolved to
    assert [d["data"] for d in saved["datasets"]] == [str(tiny_dataset), str(copy)]
    config = saved_train_config(out)
    assert config.init == tmp_path / "source" / "checkpoints" / "000004" and config.extra_data == (copy,)
    # Resuming takes its weights from the run itself, so it no longer needs the source.
    shutil.rmtree(tmp_path / "source")
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(out), "--resume"])
