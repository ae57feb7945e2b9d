"""A frozen image encoder computes each observation once inside an RL step, and nothing else changes:
the same log-probabilities, the same gradients, a learning encoder left alone."""

from __future__ import annotations

import copy

import pytest
import torch

from gymnast.policy.flow_vla import FlowVLA, FlowVLAConfig
from gymnast.policy.frozen_vision import remembered_vision
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.rl.train import learning_parameters

TWO = ("front", "gripper")


def tiny_policy(family: str = "vla"):
    torch.manual_seed(0)
    if family == "flow":
        return FlowVLA(FlowVLAConfig(width=32, layers=1, heads=2, image_size=32, cameras=TWO), pretrained_vision=False)
    return EmbeddedVLA(VLAConfig(width=32, layers=1, heads=2, image_size=32, cameras=TWO), pretrained_vision=False)


def counted(policy) -> list[int]:
    """How many images (views) the policy's encoder runs on, counted as it runs."""
    seen = [0]
    policy.vision.register_forward_hook(lambda module, inputs, output: seen.__setitem__(0, seen[0] + len(inputs[0])))
    return seen


def observations(batch: int = 4, seed: int = 0) -> torch.Tensor:
    return torch.randint(0, 256, (batch, 32, 64, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))


def update_gradients(policy, reference, obs, tokens) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """What an RL update computes: the policy's log-probabilities with their gradients, and the reference's."""
    policy.zero_grad()
    texts = ["reach"] * len(obs)
    logp = policy.log_prob(obs, texts, tokens, 1.0)
    with torch.no_grad():
        ref = reference.log_prob(obs, texts, tokens, 1.0)
    (logp.sum() - ref.sum()).backward()
    return logp.detach(), {name: p.grad.clone() for name, p in policy.named_parameters() if p.grad is not None}


@pytest.mark.parametrize("family", ["vla", "flow"])
def test_a_frozen_encoder_sees_each_image_once_and_the_update_is_unchanged(family):
    policy = tiny_policy(family)
    learning_parameters(policy, ("vision",))
    reference = copy.deepcopy(policy).requires_grad_(False)
    obs = observations()
    tokens = policy.sample(obs, ["reach"] * 4, 1.0, torch.Generator().manual_seed(1)).tokens
    expected_logp, expected_grads = update_gradients(policy, reference, obs, tokens)

    seen, seen_reference = counted(policy), counted(reference)
    with remembered_vision(policy, reference) as memories:
        policy.sample(obs, ["reach"] * 4, 1.0, torch.Generator().manual_seed(1))  # the rollout's call
        logp, grads = update_gradients(policy, reference, obs.clone(), tokens)  # the update's copy of the images
    assert len(memories) == 1  # the policy and its reference share their encoder's work
    assert seen[0] == 4 * 2 and seen_reference[0] == 0  # four observations of two views, encoded once
    assert memories[0].hits == 8 and memories[0].misses == 4
    torch.testing.assert_close(logp, expected_logp)
    assert grads.keys() == expected_grads.keys() and not any(name.startswith("vision.") for name in grads)
    for name in grads:
        torch.testing.assert_close(grads[name], expected_grads[name])
    assert policy.vision_memory is None and reference.vision_memory is None  # forgotten on leaving


def test_a_learning_encoder_and_an_encoder_of_other_weights_are_not_remembered_or_shared():
    learning = tiny_policy()
    seen = counted(learning)
    with remembered_vision(learning) as memories:
        for _ in range(2):
            learning.log_prob(observations(), ["reach"] * 4, torch.zeros(4, learning.config.num_tokens, dtype=torch.long))
    assert memories == [] and seen[0] == 2 * 4 * 2

    frozen = tiny_policy()
    learning_parameters(frozen, ("vision",))
    other = copy.deepcopy(frozen)
    with torch.no_grad():
        next(other.vision.parameters()).add_(1.0)
    with remembered_vision(frozen, other) as memories:
        assert len(memories) == 2


def test_the_same_image_is_found_in_any_batch_and_a_changed_one_is_encoded():
    policy = tiny_policy()
    learning_parameters(policy, ("vision",))
    seen = counted(policy)
    obs = observations(3)
    changed = obs.clone()
    changed[1, 0, 40, 0] ^= 1  # one byte of the second image's gripper view
    text = policy.embed_instructions(["reach"] * 3, 3)
    with remembered_vision(policy) as (memory,):
        first = policy.memory(obs, text)
        again = policy.memory(torch.stack([obs[2], obs[0], changed[1]]), text[[2, 0, 1]])
    assert (memory.misses, memory.hits) == (4, 2) and seen[0] == 4 * 2
    torch.testing.assert_close(again[:2], first[[2, 0]])
    assert not torch.equal(again[2], first[1])
