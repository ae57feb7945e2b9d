"""World-model ensembles: the first member's frames, the members' disagreement, the directory format, eval-wm."""

import json
import shutil

import pytest
import torch

from gymnast.cli import main
from gymnast.utils.checkpoint import save_checkpoint
from gymnast.world_model.base import load_world_model, rollout
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.ensemble import EnsembleWorldModel, frame_disagreement, write_ensemble
from gymnast.world_model.evaluate import heldout_fraction

TINY = EmbeddedWorldModelConfig(image_size=32, latent_channels=16, widths=(8, 16), blocks=1, action_width=16, bf16=False)


def make_model(seed: int = 0, config: EmbeddedWorldModelConfig = TINY) -> EmbeddedWorldModel:
    torch.manual_seed(seed)
    model = EmbeddedWorldModel(config)
    for block in model.blocks:  # a fresh model's blocks are the identity; give them weights, as training would
        torch.nn.init.normal_(block.conv2.weight, std=0.1)
    return model.eval()


def frames(batch: int, count: int) -> torch.Tensor:
    return torch.randint(0, 256, (batch, count, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))


def actions(batch: int, steps: int) -> torch.Tensor:
    return torch.rand(batch, steps, 4, generator=torch.Generator().manual_seed(1)) * 2 - 1


def save_run(run, model: EmbeddedWorldModel, heldout: float = 0.25) -> None:
    save_checkpoint(run, 1, model, {"model": model.spec(), "train": {"heldout_fraction": heldout}})


def test_disagreement_is_the_mean_per_pixel_standard_deviation_across_members():
    black, white = torch.zeros(1, 2, 4, 4, 3, dtype=torch.uint8), torch.full((1, 2, 4, 4, 3), 255, dtype=torch.uint8)
    torch.testing.assert_close(frame_disagreement([black, white]), torch.full((1, 2), 0.5))
    torch.testing.assert_close(frame_disagreement([white, white, white]), torch.zeros(1, 2))


def test_identical_members_agree_and_the_ensemble_imagines_what_a_member_does():
    member = make_model()
    ensemble = EnsembleWorldModel([member, make_model()])
    state, imagined = ensemble.step(ensemble.init_state(frames(3, 2)), actions(3, 5))
    assert torch.equal(imagined, member.step(member.init_state(frames(3, 2)), actions(3, 5))[1])
    assert state.disagreement.shape == (3, 5) and torch.equal(state.disagreement, torch.zeros(3, 5))


def test_different_members_disagree_and_the_first_one_leads():
    first, second = make_model(seed=0), make_model(seed=1)
    ensemble = EnsembleWorldModel([first, second])
    state = ensemble.init_state(frames(2, 2))
    state, imagined = ensemble.step(state, actions(2, 3))
    assert torch.equal(imagined, first.step(first.init_state(frames(2, 2)), actions(2, 3))[1])
    assert (state.disagreement > 0).all()
    state, more = ensemble.step(state, actions(2, 2))  # each call reports its own frames' disagreement
    assert state.disagreement.shape == (2, 2) and more.shape == (2, 2, 32, 32, 3)
    assert rollout(ensemble, frames(2, 1), actions=actions(2, 4)).frames.shape == (2, 4, 32, 32, 3)


def test_members_must_make_the_same_frames_from_the_same_actions():
    with pytest.raises(ValueError, match="image_size differ"):
        EnsembleWorldModel([make_model(), make_model(config=EmbeddedWorldModelConfig(**{**TINY.__dict__, "image_size": 16}))])
    with pytest.raises(ValueError, match="at least two members"):
        EnsembleWorldModel([make_model()])


def test_an_ensemble_directory_loads_through_load_world_model(tmp_path):
    first, second = make_model(seed=0), make_model(seed=1)
    save_run(tmp_path / "runs" / "a", first)
    save_run(tmp_path / "runs" / "b", second, heldout=0.5)
    write_ensemble(tmp_path / "ens", [tmp_path / "runs" / "a", tmp_path / "runs" / "b"])
    assert json.loads((tmp_path / "ens" / "ensemble.json").read_text()) == {
        "backend": "ensemble", "members": ["../runs/a", "../runs/b"]}
    shutil.move(tmp_path / "runs", tmp_path / "moved" / "runs")  # relative members move with the ensemble
    shutil.move(tmp_path / "ens", tmp_path / "moved" / "ens")
    loaded = load_world_model(tmp_path / "moved" / "ens", reanchor_every=8)
    assert isinstance(loaded, EnsembleWorldModel) and [m.config.reanchor_every for m in loaded.members] == [8, 8]
    context, moves = frames(2, 2), actions(2, 4)
    assert torch.equal(loaded.step(loaded.init_state(context), moves)[1], first.step(first.init_state(context), moves)[1])
    assert heldout_fraction(tmp_path / "moved" / "ens") == 0.25  # scenes held out of every member
    assert isinstance(load_world_model(tmp_path / "moved" / "runs" / "a"), EmbeddedWorldModel)  # runs load as before


def test_a_malformed_ensemble_file_is_a_clear_error(tmp_path):
    (tmp_path / "ensemble.json").write_text(json.dumps({"backend": "ensemble", "members": ["only-one"]}))
    with pytest.raises(ValueError, match="two or more run paths"):
        load_world_model(tmp_path)


def test_cli_make_ensemble_then_eval_wm_reports_disagreement(tiny_dataset, tmp_path, capsys):
    save_run(tmp_path / "a", make_model(seed=0))
    save_run(tmp_path / "b", make_model(seed=1))
    main(["make-ensemble", "--members", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "ens")])
    assert "ensemble of 2 world models" in capsys.readouterr().out
    main(["eval-wm", "--wm", str(tmp_path / "ens"), "--data", str(tiny_dataset), "--out", str(tmp_path / "e.json"),
          "--videos", "0", "--control-scenes", "0"])
    assert "ensemble disagreement" in capsys.readouterr().out
    report = json.loads((tmp_path / "e.json").read_text())
    for key in ("psnr_h1", "psnr_h32", "moving_psnr_h32", "copy_last_psnr_h32", "disagreement_h1", "disagreement_h32",
                "disagreement_full", "disagreement_error_corr", "disagreement_error_spearman",
                "disagreement_error_corr_same_step"):
        assert key in report, key
    assert report["disagreement_h1"] > 0 and -1 <= report["disagreement_error_corr"] <= 1
    assert report["model"]["backend"] == "ensemble" and "disagreement_h1" in report["per_task"]["drawer-close-v3"]
