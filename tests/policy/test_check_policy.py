"""`gymnast check-policy` names each breach of the Policy contract with what to change, and the
built-in policies keep it."""

import pytest
import torch

import policy_stand_ins as stand_ins
from gymnast.cli import main
from gymnast.policy.check import check_policy
from gymnast.policy.flow_vla import FlowVLA, FlowVLAConfig
from gymnast.policy.vla import EmbeddedVLA, VLAConfig


def only_breach(policy, rule: str) -> str:
    breaches = check_policy(policy)
    assert {breach.rule for breach in breaches} == {rule}, [str(b) for b in breaches]
    return breaches[0].message


@pytest.mark.parametrize("name", ["tokens", "flow", "tokens with a state", "the example's own"])
def test_the_built_in_policies_and_the_examples_keep_the_contract(name):
    torch.manual_seed(0)
    policy = {
        "tokens": lambda: EmbeddedVLA(VLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32)),
        "flow": lambda: FlowVLA(FlowVLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32, steps=3),
                                pretrained_vision=False),
        "tokens with a state": lambda: EmbeddedVLA(VLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32,
                                                             state_dim=4)),
        "the example's own": stand_ins.small,
    }[name]().eval()
    assert check_policy(policy) == []


def test_a_log_prob_that_forgets_the_temperature_differs_from_the_sampled_logp():
    message = only_breach(stand_ins.make(stand_ins.ForgetsTheTemperature), "log_prob")
    assert "differs from the logp it returned" in message and "divided by the temperature" in message


def test_a_greedy_act_that_samples_is_not_deterministic():
    message = only_breach(stand_ins.make(stand_ins.SamplesWhenGreedy), "act_deterministic")
    assert "argmax" in message


def test_a_chunk_other_than_declared_is_named_with_the_expected_shape():
    message = only_breach(stand_ins.make(stand_ins.DeclaresAnotherChunk), "action_shape")
    assert "expected (2, 4, 4)" in message and "declare the chunk_size" in message


def test_a_sample_that_ignores_the_generator_is_not_reproducible():
    message = only_breach(stand_ins.make(stand_ins.IgnoresTheGenerator), "generator")
    assert "generator passed to sample()" in message


def test_a_declared_state_that_is_never_asked_for_is_named():
    message = only_breach(stand_ins.make(stand_ins.ReadsNoStateItDeclares), "state")
    assert "state_dim=3" in message and "raises ValueError without it" in message


def test_the_command_loads_by_python_path_and_exits_1_naming_the_breach(capsys):
    main(["check-policy", "--policy", "python:policy_stand_ins:small"])
    assert "keeps the contract" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_:
        main(["check-policy", "--policy", "python:policy_stand_ins:forgets_the_temperature"])
    assert exit_.value.code == 1 and "[log_prob]" in capsys.readouterr().out
