"""The flow world model honours the WorldModel contract, samples reproducibly, and trains through train-wm."""

import dataclasses
import json

import pytest
import torch
from resumed_runs import assert_resumed_as_whole, stop_after

from gymnast.cli import main
from gymnast.utils.checkpoint import save_checkpoint
from gymnast.utils.metrics import read_metrics
from gymnast.world_model.base import load_world_model, rollout
from gymnast.world_model.flow import FlowWorldModel, FlowWorldModelConfig
from gymnast.world_model.train import FLOW_PRESETS, train_world_model, wm_preset

TINY = FlowWorldModelConfig(image_size=32, latent_channels=4, widths=(8, 16), width=16, blocks=1, condition_width=16,
                            sample_steps=2, bf16=False)
DEBUG = dataclasses.replace(FLOW_PRESETS["debug"], heldout_fraction=0.25)


def make_model(config: FlowWorldModelConfig = TINY) -> FlowWorldModel:
    torch.manual_seed(0)
    model = FlowWorldModel(config)
    # A fresh model's blocks are the identity (zero-initialised output convolutions), so its
    # velocity would ignore the action; give them weights, as training would.
    for block in model.blocks:
        torch.nn.init.normal_(block.conv2.weight, std=0.1)
    return model.eval()


def frames(batch: int, count: int, seed: int = 0) -> torch.Tensor:
    return torch.randint(0, 256, (batch, count, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))


def actions(batch: int, steps: int, seed: int = 1) -> torch.Tensor:
    return torch.rand(batch, steps, 4, generator=torch.Generator().manual_seed(seed)) * 2 - 1


def seeded(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_step_samples_one_uint8_frame_per_action():
    model = make_model()
    state, imagined = model.step(model.init_state(frames(3, 1)), actions(3, 5), generator=seeded(0))
    assert imagined.shape == (3, 5, 32, 32, 3) and imagined.dtype == torch.uint8
    assert state.latents.shape == (3, 2, 4, 4, 4)
    assert state.select(slice(0, 2)).latents.shape[0] == 2


def test_the_same_seed_gives_the_same_rollout_and_another_seed_another():
    model = make_model()
    a = rollout(model, frames(2, 2), actions(2, 6), generator=seeded(3)).frames
    b = rollout(model, frames(2, 2), actions(2, 6), generator=seeded(3)).frames
    c = rollout(model, frames(2, 2), actions(2, 6), generator=seeded(4)).frames
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_stepping_in_chunks_draws_what_one_long_step_draws():
    model = make_model()
    state = model.init_state(frames(2, 2))
    whole = model.step(state, actions(2, 6), generator=seeded(5))[1]
    generator = seeded(5)
    middle, first = model.step(state, actions(2, 6)[:, :3], generator=generator)
    second = model.step(middle, actions(2, 6)[:, 3:], generator=generator)[1]
    assert torch.equal(whole, torch.cat([first, second], dim=1))


def test_different_actions_imagine_different_futures():
    model = make_model()
    state = model.init_state(frames(1, 2))
    one = model.step(state, actions(1, 4, seed=1), generator=seeded(0))[1]
    other = model.step(state, actions(1, 4, seed=2), generator=seeded(0))[1]
    assert not torch.equal(one, other)


def test_guidance_extrapolates_from_the_action_free_velocity():
    plain, guided = make_model(), make_model(dataclasses.replace(TINY, guidance=3.0))
    context, moves = frames(2, 2), actions(2, 3)
    a = rollout(plain, context, moves, generator=seeded(0)).frames
    b = rollout(guided, context, moves, generator=seeded(0)).frames
    assert a.shape == b.shape and not torch.equal(a, b)


def test_checkpoint_round_trip_gives_the_same_model(tmp_path):
    model = make_model()
    save_checkpoint(tmp_path, 1, model, {"model": model.spec()})
    loaded = load_world_model(tmp_path)
    assert isinstance(loaded, FlowWorldModel) and loaded.config == model.config
    context, moves = frames(2, 2), actions(2, 3)
    assert torch.equal(rollout(model, context, moves, seeded(1)).frames, rollout(loaded, context, moves, seeded(1)).frames)
    faster = load_world_model(tmp_path, sample_steps=1)
    assert faster.config.sample_steps == 1


def test_bad_inputs_are_refused_with_their_shapes():
    model = make_model()
    with pytest.raises(ValueError, match=r"\(B, C, 32, 32, 3\) uint8"):
        model.init_state(frames(1, 1).float())
    with pytest.raises(ValueError, match=r"\(2, K, 4\) float"):
        model.step(model.init_state(frames(2, 1)), actions(3, 2))
    with pytest.raises(ValueError, match="context_noise"):
        FlowWorldModelConfig(context_noise=0.5, max_context_noise=0.3)


def test_presets_belong_to_a_backend():
    assert wm_preset("gpu", "flow").backend == "flow" and wm_preset("gpu").backend == "embedded"
    with pytest.raises(ValueError, match="no preset 'huge'"):
        wm_preset("huge", "flow")


def test_training_lowers_both_losses(tiny_dataset, tmp_path):
    config = dataclasses.replace(DEBUG, steps=40, lr=3e-3, log_every=1, validate_every=40, video_every=40, checkpoint_every=40)
    train_world_model(tiny_dataset, tmp_path, config, progress=False)
    rows = read_metrics(tmp_path)
    for name in ("train/recon_loss", "train/flow_loss"):
        values = [row[name] for row in rows]
        assert sum(values[-8:]) < 0.9 * sum(values[:8]), name  # the flow loss has a floor: the noise it cannot predict


def test_resume_from_a_checkpoint_continues_exactly(tiny_dataset, tmp_path):
    whole, interrupted = tmp_path / "whole", tmp_path / "interrupted"
    train_world_model(tiny_dataset, whole, DEBUG, progress=False)
    stop_after(whole, interrupted, step=2, metric_lines=2)
    train_world_model(tiny_dataset, interrupted, DEBUG, resume=True, progress=False)
    assert_resumed_as_whole(whole, interrupted, final_step=4)


def test_cli_train_wm_flow_then_eval_wm(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "wm"
    main(["train-wm", "--backend", "flow", "--data", str(tiny_dataset), "--out", str(run), "--preset", "debug"])
    assert "world model:" in capsys.readouterr().out
    assert json.loads((run / "config.json").read_text())["model"]["backend"] == "flow"
    main(["train-wm", "--out", str(run), "--resume"])  # the backend comes from the run
    with pytest.raises(SystemExit):
        main(["train-wm", "--out", str(run), "--resume", "--backend", "embedded"])
    assert "--backend embedded disagrees with the run" in capsys.readouterr().err
    heldout = tmp_path / "heldout"  # the CLI's held-out share of 10% leaves no scene of the tiny dataset out
    train_world_model(tiny_dataset, heldout, DEBUG, progress=False)
    main(["eval-wm", "--wm", str(heldout), "--data", str(tiny_dataset), "--out", str(tmp_path / "eval.json"),
          "--videos", "1", "--control-scenes", "1"])
    report = json.loads((tmp_path / "eval.json").read_text())
    assert report["model"]["backend"] == "flow" and "moving_psnr_h32" in report
