"""The flow-matching VLA: the density of a sampled denoising path, the deterministic sampler,
the flow-matching loss, persistence."""

from __future__ import annotations

import pytest
import torch
from torch.distributions import Normal

from gymnast.policy.flow_vla import FlowVLA, FlowVLAConfig

TINY = FlowVLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32, steps=3)


def make(seed: int = 0, config: FlowVLAConfig = TINY) -> FlowVLA:
    torch.manual_seed(seed)
    return FlowVLA(config, pretrained_vision=False).eval()


def observations(batch: int = 2) -> tuple[torch.Tensor, list[str]]:
    images = torch.randint(0, 256, (batch, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    return images, (["open the drawer", "push the puck to the green marker"] * batch)[:batch]


def _trained_sigma(model: FlowVLA) -> FlowVLA:
    """Noise that differs per element and step, so the density test is not about a constant."""
    with torch.no_grad():
        model.sigma.weight.normal_(0, 0.5)
    return model


@pytest.mark.parametrize("temperature", [0.7, 1.0, 1.5])
def test_the_log_prob_of_a_sampled_path_is_its_density_computed_step_by_step(temperature):
    model = _trained_sigma(make())
    obs, texts = observations()
    sample = model.sample(obs, texts, temperature, generator=torch.Generator().manual_seed(5))
    steps, k, a = TINY.steps, TINY.chunk_size, TINY.action_dim
    path = sample.tokens.view(2, steps + 1, k, a)
    with torch.no_grad():
        memory = model.observe(obs, texts)
        by_hand = Normal(0.0, 1.0).log_prob(path[:, 0])
        for i in range(steps):
            velocity, sigma = model.field(memory, path[:, i], torch.full((2,), i / steps))
            by_hand += Normal(path[:, i] + velocity / steps, temperature * sigma).log_prob(path[:, i + 1])
    assert sample.logp.shape == (2, k * a)  # one value per action element, chunk-major like tokens
    torch.testing.assert_close(sample.logp, by_hand.flatten(1))
    torch.testing.assert_close(model.log_prob(obs, texts, sample.tokens, temperature), sample.logp)


def test_the_sampled_chunk_is_the_end_of_its_path_in_action_units():
    config = FlowVLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32, steps=3,
                           low=(-2.0, 0.0, -1.0, 10.0), high=(2.0, 1.0, 1.0, 20.0))
    model = make(config=config)
    obs, texts = observations()
    sample = model.sample(obs, texts, 1.0, generator=torch.Generator().manual_seed(0))
    end = sample.tokens.view(2, 4, 3, 4)[:, -1].clamp(-1, 1)
    low, high = torch.tensor(config.low), torch.tensor(config.high)
    torch.testing.assert_close(sample.actions, low + (end + 1) / 2 * (high - low))


def test_sampling_repeats_for_a_seed_and_the_deterministic_sampler_needs_none():
    model = make()
    obs, texts = observations()
    first, second = (model.sample(obs, texts, 1.0, generator=torch.Generator().manual_seed(9)) for _ in range(2))
    torch.testing.assert_close(first.tokens, second.tokens)
    other = model.sample(obs, texts, 1.0, generator=torch.Generator().manual_seed(10))
    assert not torch.equal(first.tokens, other.tokens)
    torch.testing.assert_close(model.act(obs, texts), model.act(obs, texts), rtol=0, atol=0)
    with pytest.raises(ValueError, match="use act"):
        model.sample(obs, texts, 0.0)


def test_the_policy_gradient_reaches_the_noise_network_and_the_velocity():
    model = make().train()
    obs, texts = observations()
    sample = model.sample(obs, texts, 1.0, generator=torch.Generator().manual_seed(2))
    model.log_prob(obs, texts, sample.tokens).sum().backward()
    assert model.sigma.weight.grad.abs().sum() > 0 and model.velocity.weight.grad.abs().sum() > 0


def test_entropy_grows_with_temperature():
    model = make()
    obs, texts = observations()
    sample = model.sample(obs, texts, 1.0, generator=torch.Generator().manual_seed(2))
    cold = model.log_prob_and_entropy(obs, texts, sample.tokens, 0.5)[1]
    hot = model.log_prob_and_entropy(obs, texts, sample.tokens, 2.0)[1]
    assert cold.shape == (2, 12) and bool((hot > cold).all())


def test_flow_matching_fits_expert_chunks_and_ignores_padding():
    model = make().train()
    obs, texts = observations()
    experts = torch.tensor([[0.5, -0.5, 0.2, 0.9]]).expand(2, 3, 4).clone()
    valid = torch.tensor([[True, True, True], [True, False, False]])
    padded = experts.clone()
    padded[1, 1:] = 123.0  # beyond the episode's end: must not matter
    same = torch.Generator().manual_seed(4), torch.Generator().manual_seed(4)
    torch.testing.assert_close(model.flow_loss(obs, texts, experts, valid, same[0]),
                               model.flow_loss(obs, texts, padded, valid, same[1]))
    generator = torch.Generator().manual_seed(0)
    before = (model.eval().act(obs, texts) - experts).abs().max()
    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(100):  # the last 50 steps' loss: about a quarter of the first 10's
        loss = model.flow_loss(obs, texts, experts, valid, generator)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert sum(losses[-50:]) / 50 < 0.3 * sum(losses[:10]) / 10
    assert (model.eval().act(obs, texts) - experts).abs().max() < 0.5 * before


def test_a_saved_flow_policy_loads_with_its_sampler(tmp_path):
    from gymnast.utils.checkpoint import save_checkpoint
    from gymnast.policy.load import load_policy

    model = _trained_sigma(make())
    save_checkpoint(tmp_path, 1, model, {"model": model.spec()})
    loaded = load_policy(tmp_path)
    assert isinstance(loaded, FlowVLA) and loaded.config == TINY
    obs, texts = observations()
    torch.testing.assert_close(loaded.act(obs, texts), model.act(obs, texts))
