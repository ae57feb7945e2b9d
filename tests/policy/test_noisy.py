"""NoisyPolicy: the base's greedy actions plus seeded Gaussian noise, clipped; random actions at inf."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import pytest
import torch

from gymnast.config import EnvConfig
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.envs.starts import evaluation_starts
from gymnast.eval.evaluate import EvalConfig, evaluate
from gymnast.policy.noisy import RANDOM, NoisyPolicy
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.rl.rollout import collect_rollouts

TINY = VLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32)


def tiny_vla() -> EmbeddedVLA:
    torch.manual_seed(0)
    return EmbeddedVLA(TINY, pretrained_vision=False).eval()


def observations(batch: int = 4) -> tuple[torch.Tensor, list[str]]:
    images = torch.randint(0, 256, (batch, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    return images, ["open the drawer"] * batch


class ConstantPolicy:
    """A base whose greedy chunk is always `value`; counts its calls."""

    chunk_size, action_dim = 5, 4

    def __init__(self, value: float = 0.0) -> None:
        self.value, self.calls = value, 0

    def act(self, obs: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        self.calls += 1
        return torch.full((len(obs), self.chunk_size, self.action_dim), self.value)


def test_noise_zero_acts_exactly_as_the_base_policy():
    base = tiny_vla()
    obs, texts = observations()
    noisy = NoisyPolicy(base, 0.0)
    torch.testing.assert_close(noisy.act(obs, texts), base.act(obs, texts), rtol=0, atol=0)
    assert (noisy.chunk_size, noisy.action_dim, noisy.config) == (base.chunk_size, base.action_dim, base.config)
    torch.testing.assert_close(noisy.chunk_tokens(base.act(obs, texts)), base.chunk_tokens(base.act(obs, texts)))


def test_the_same_seed_gives_the_same_actions_and_reseed_repeats_them():
    base, (obs, texts) = tiny_vla(), observations()
    first, second = NoisyPolicy(base, 0.3, seed=7), NoisyPolicy(base, 0.3, seed=7)
    draws = [first.act(obs, texts) for _ in range(3)]
    assert all(torch.equal(a, second.act(obs, texts)) for a in draws)
    assert not torch.equal(draws[0], draws[1])  # the stream moves on between calls
    first.reseed()
    assert torch.equal(first.act(obs, texts), draws[0])
    assert not torch.equal(NoisyPolicy(base, 0.3, seed=8).act(obs, texts), draws[0])


def test_the_noise_is_drawn_from_its_own_generator_only():
    base, (obs, texts) = tiny_vla(), observations()
    torch.manual_seed(0)
    a = NoisyPolicy(base, 0.3).act(obs, texts)
    torch.manual_seed(123)
    assert torch.equal(NoisyPolicy(base, 0.3).act(obs, texts), a)


def test_more_noise_spreads_the_actions_more_around_the_greedy_ones():
    obs, texts = torch.zeros(200, 32, 32, 3, dtype=torch.uint8), ["reach the goal"] * 200
    spreads = [NoisyPolicy(ConstantPolicy(0.0), noise).act(obs, texts).std().item() for noise in (0.05, 0.2, 0.5, 2.0)]
    assert spreads == sorted(spreads)
    assert spreads[0] == pytest.approx(0.05, rel=0.05) and spreads[1] == pytest.approx(0.2, rel=0.05)


def test_actions_stay_in_the_action_range():
    obs, texts = torch.zeros(100, 32, 32, 3, dtype=torch.uint8), ["reach the goal"] * 100
    for value in (-1.0, 0.9, 1.0):
        actions = NoisyPolicy(ConstantPolicy(value), 3.0).act(obs, texts)
        assert actions.min() >= -1 and actions.max() <= 1
        assert (actions == -1).any() and (actions == 1).any()  # big noise reaches both bounds


def test_infinite_noise_draws_uniform_actions_without_the_base():
    base = ConstantPolicy(0.7)
    floor = NoisyPolicy(base, RANDOM)
    actions = floor.act(torch.zeros(500, 32, 32, 3, dtype=torch.uint8), ["reach the goal"] * 500)
    assert floor.random and base.calls == 0 and actions.shape == (500, 5, 4)
    assert actions.min() >= -1 and actions.max() <= 1
    assert actions.mean().item() == pytest.approx(0.0, abs=0.02)
    assert actions.std().item() == pytest.approx(1 / math.sqrt(3), rel=0.02)  # uniform on [-1, 1]


@pytest.mark.parametrize("noise", [-0.1, float("nan")])
def test_a_negative_or_nan_noise_is_refused(noise):
    with pytest.raises(ValueError, match="noise must be >= 0"):
        NoisyPolicy(ConstantPolicy(), noise)


def test_sampling_and_log_probs_are_refused_with_a_reason():
    noisy, (obs, texts) = NoisyPolicy(tiny_vla(), 0.2), observations()
    with pytest.raises(NotImplementedError, match="only acts greedily for evaluation"):
        noisy.sample(obs, texts)
    with pytest.raises(NotImplementedError, match="log_prob"):
        noisy.log_prob(obs, texts, torch.zeros(4, 12, dtype=torch.int64))


def test_gymnast_eval_runs_a_noisy_policy_in_process(tmp_path: Path):
    config = EvalConfig(tasks="reach-v3", episodes=1, workers=1, videos_per_task=0,
                        env=EnvConfig(image_size=32, horizon=12))
    report = evaluate(NoisyPolicy(tiny_vla(), 0.5), config, tmp_path / "noisy.json", progress=False)
    assert report["episodes"] == 1 and report["real_interactions"] == 12
    assert "NoisyPolicy (in-process)" in report["policy"]


def test_greedy_rollouts_execute_the_noisy_actions_and_repeat_after_reseed():
    env_config = EnvConfig(image_size=32, horizon=9)
    starts = evaluation_starts(["reach-v3"], 2, env_config)
    base = tiny_vla()
    noisy = NoisyPolicy(base, 0.5, seed=1)
    with SimVectorEnv(2, TINY.chunk_size, env_config) as env:
        plain = collect_rollouts(env, base, starts, 0.0, torch.Generator())
        first = collect_rollouts(env, noisy, starts, 0.0, torch.Generator())
        noisy.reseed()
        again = collect_rollouts(env, noisy, starts, 0.0, torch.Generator())
    assert torch.equal(first.actions, again.actions) and not torch.equal(first.actions, plain.actions)
    assert first.actions.abs().max() <= 1 and first.tokens.shape == plain.tokens.shape
