"""Iter-SFT's pieces: rollouts become SFT samples, batches mix them 1:1 with demonstrations, and
fine-tuning starts from the given policy."""

import dataclasses

import numpy as np
import pytest
import torch

from gymnast.envs.starts import Start
from gymnast.experiment.iter_sft import rollout_samples
from gymnast.policy.sft import SFT_PRESETS, DemoSet, _batch_pool, train_sft
from gymnast.rl.rollout import Rollouts


def _rollouts(lengths, calls=3, chunk=2, size=8):
    count = len(lengths)
    starts = tuple(Start("reach-v3", i, f"say {i % 2}", np.zeros((1, size, size, 3), np.uint8), np.zeros((0, 4), np.float32))
                   for i in range(count))
    observations = torch.arange(count * calls).view(count, calls, 1, 1, 1).expand(count, calls, size, size, 3).to(torch.uint8)
    actions = torch.arange(count * calls * chunk * 4, dtype=torch.float32).view(count, calls * chunk, 4)
    return Rollouts(starts, observations, torch.zeros(count, calls, chunk * 4, dtype=torch.long),
                    torch.zeros(count, calls, chunk * 4), torch.ones(count, calls, chunk * 4, dtype=torch.bool),
                    torch.zeros(count, calls * chunk + 1, size, size, 3, dtype=torch.uint8), actions,
                    torch.tensor(lengths), None, None)


def test_every_executed_call_becomes_one_sample_with_its_chunk():
    rollouts = _rollouts([6, 3])  # the second rollout ends in the middle of its second call
    samples = rollout_samples(rollouts, chunk_size=2)
    assert len(samples.images) == 3 + 2  # calls that executed at least one action
    torch.testing.assert_close(samples.chunks[1], rollouts.actions[0, 2:4])  # first rollout, second call
    assert samples.valid[4].tolist() == [True, False]  # action 3 was the last one executed
    assert samples.images[3, 0, 0, 0].item() == rollouts.observations[1, 0, 0, 0, 0].item()
    assert [samples.instructions[i] for i in samples.instruction.tolist()] == ["say 0"] * 3 + ["say 1"] * 2


def test_a_batch_takes_half_from_the_demonstrations_and_half_from_the_extra_samples():
    demos = DemoSet(torch.zeros(10, 8, 8, 3, dtype=torch.uint8), torch.zeros(10, 2, 4), torch.ones(10, 2, dtype=torch.bool),
                    torch.zeros(10, dtype=torch.long), ["reach"], [])
    extra = rollout_samples(_rollouts([6, 6]), chunk_size=2)
    pool, draw = _batch_pool(demos, extra, batch_size=8)
    batch = draw(torch.Generator().manual_seed(0))
    assert (batch[:4] < 10).all() and (batch[4:] >= 10).all() and len(pool.images) == 16
    assert pool.instructions == ["reach", "say 0", "say 1"]
    assert [pool.instructions[i] for i in pool.instruction[10:].tolist()] == ["say 0"] * 3 + ["say 1"] * 3


def test_mismatched_extra_samples_are_refused_with_their_shapes():
    demos = DemoSet(torch.zeros(2, 16, 16, 3, dtype=torch.uint8), torch.zeros(2, 2, 4), torch.ones(2, 2, dtype=torch.bool),
                    torch.zeros(2, dtype=torch.long), ["reach"], [])
    with pytest.raises(ValueError, match=r"extra samples have images \(8, 8, 3\)"):
        _batch_pool(demos, rollout_samples(_rollouts([6]), chunk_size=2), batch_size=4)


def test_fine_tuning_starts_from_the_given_policy(tiny_dataset, tmp_path):
    from gymnast.policy.load import load_policy

    config = dataclasses.replace(SFT_PRESETS["debug"], steps=2, checkpoint_every=2, demos_per_task=1)
    first = train_sft(tiny_dataset, tmp_path / "first", config, progress=False)
    policy = load_policy(first)
    extra = rollout_samples(_rollouts([4], calls=2, chunk=policy.chunk_size, size=32), policy.chunk_size)
    frozen = dataclasses.replace(config, lr=0.0, seed=7)  # nothing moves: the result is the starting point
    second = train_sft(tiny_dataset, tmp_path / "second", frozen, progress=False, init=first, extra=extra)
    for key, value in load_policy(second).state_dict().items():
        torch.testing.assert_close(value, policy.state_dict()[key], msg=key)
