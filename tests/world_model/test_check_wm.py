"""`gymnast check-wm` names each breach of the WorldModel contract with what to change, and every
built-in backend keeps it."""

import pytest
import torch

import wm_stand_ins as stand_ins
from gymnast.cli import main
from gymnast.world_model.check import check_world_model
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.ensemble import EnsembleWorldModel
from gymnast.world_model.flow import FlowWorldModel, FlowWorldModelConfig
from gymnast.world_model.views import MultiViewWorldModel

TINY = dict(image_size=16, latent_channels=8, widths=(8, 8), blocks=1, action_width=8, bf16=False)


def rules(model) -> list[str]:
    return [breach.rule for breach in check_world_model(model, actions=2)]


def only_breach(model, rule: str):
    breaches = check_world_model(model)
    assert [breach.rule for breach in breaches] == [rule], [str(b) for b in breaches]
    return breaches[0].message


def embedded(**settings) -> EmbeddedWorldModel:
    torch.manual_seed(0)
    return EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY, **settings)).eval()


@pytest.mark.parametrize("name", ["embedded", "frame per chunk", "grounded", "flow", "ensemble", "two cameras"])
def test_every_built_in_backend_keeps_the_contract(name):
    torch.manual_seed(0)
    model = {
        "embedded": embedded,
        "frame per chunk": lambda: embedded(actions_per_frame=5),
        "grounded": lambda: embedded(state_dim=3, state_mean=(0.0,) * 3, state_std=(1.0,) * 3),
        "flow": lambda: FlowWorldModel(FlowWorldModelConfig(image_size=16, action_dim=4, latent_channels=4, widths=(8, 8),
                                                            width=16, blocks=1, condition_width=16, sample_steps=2,
                                                            bf16=False)).eval(),
        "ensemble": lambda: EnsembleWorldModel([embedded(), embedded()]),
        "two cameras": lambda: MultiViewWorldModel(embedded(), ("front", "gripper")),
    }[name]()
    assert rules(model) == []


def test_a_stand_in_that_keeps_the_contract_passes():
    assert rules(stand_ins.StandIn()) == []


def test_float_frames_are_named_with_the_conversion_to_uint8():
    message = only_breach(stand_ins.FloatFrames(), "frames_dtype")
    assert "torch.float32 frames" in message and ".to(torch.uint8)" in message


def test_frames_of_another_size_are_named_with_the_declared_size():
    message = only_breach(stand_ins.OtherSize(), "frames_shape")
    assert "(2, 5, 8, 8, 3)" in message and "expected (2, 5, 16, 16, 3)" in message and "image_size 16" in message


def test_a_state_changed_in_place_is_caught_by_two_continuations():
    message = only_breach(stand_ins.ChangesStateInPlace(), "state_in_place")
    assert "return a new state" in message


def test_a_model_that_ignores_the_generator_is_not_reproducible():
    message = only_breach(stand_ins.IgnoresGenerator(), "generator")
    assert "generator=generator" in message


def test_the_wrong_action_width_names_the_width_the_model_takes():
    message = only_breach(stand_ins.OtherActionWidth(), "action_width")
    assert "action_dim=3" in message and "declare action_dim=4" in message


def test_a_batch_whose_rows_mix_differs_from_batches_of_one():
    message = only_breach(stand_ins.MixesRows(), "batch")
    assert "its own context and actions" in message


def test_a_context_shorter_than_declared_must_be_accepted():
    message = only_breach(stand_ins.RefusesShortContext(), "short_context")
    assert "context_frames=2" in message and "pad_context" in message


def test_onload_must_restore_the_model():
    message = only_breach(stand_ins.ForgetsOnload(), "offload")
    assert "onload() must restore" in message


def test_the_command_loads_by_python_path_and_exits_1_naming_the_breach(capsys):
    main(["check-wm", "--wm", "python:wm_stand_ins:stand_in"])
    assert "keeps the contract" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_:
        main(["check-wm", "--wm", "python:wm_stand_ins:float_frames"])
    assert exit_.value.code == 1 and "[frames_dtype]" in capsys.readouterr().out


def test_a_factory_that_returns_no_world_model_is_refused_naming_what_it_lacks(capsys):
    with pytest.raises(SystemExit):
        main(["check-wm", "--wm", "python:wm_stand_ins:missing_parts"])
    assert "lacks context_frames, image_size, action_dim, init_state, step" in capsys.readouterr().err
