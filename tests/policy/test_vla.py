"""The embedded VLA: the Policy contract, sampling maths, temperature, persistence."""

from __future__ import annotations

import torch

from gymnast.policy.text import InstructionEncoder
from gymnast.policy.load import load_policy
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.utils.checkpoint import save_checkpoint

TINY = VLAConfig(width=32, layers=1, heads=2, chunk_size=3, image_size=32)


def make(seed: int = 0, config: VLAConfig = TINY) -> EmbeddedVLA:
    torch.manual_seed(seed)
    return EmbeddedVLA(config).eval()


def observations(batch: int = 2) -> tuple[torch.Tensor, list[str]]:
    images = torch.randint(0, 256, (batch, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    return images, ["open the drawer", "push the puck to the green marker"][:batch] * (batch // 2 or 1)


def test_sample_returns_a_chunk_of_tokens_with_their_log_probs():
    model = make()
    obs, texts = observations()
    sample = model.sample(obs, texts, temperature=1.0, generator=torch.Generator().manual_seed(0))
    assert sample.actions.shape == (2, 3, 4) and sample.tokens.shape == sample.logp.shape == (2, 12)
    assert sample.actions.abs().max() <= 1.0
    torch.testing.assert_close(model.tokenizer.decode(sample.tokens.view(2, 3, 4)), sample.actions)


def test_log_prob_equals_the_sampling_distribution_at_every_temperature():
    model = make()
    obs, texts = observations()
    for temperature in (0.5, 1.0, 1.6):
        sample = model.sample(obs, texts, temperature, generator=torch.Generator().manual_seed(3))
        torch.testing.assert_close(model.log_prob(obs, texts, sample.tokens, temperature), sample.logp)


def test_sampled_token_frequencies_match_the_predicted_probabilities():
    model = make()
    obs, texts = observations(1)
    probs = torch.softmax(model.logits(obs, texts)[0, 0].float(), dim=-1)
    many = 4000
    tokens = model.sample(obs.expand(many, -1, -1, -1), texts * many, 1.0, torch.Generator().manual_seed(0)).tokens
    frequencies = torch.bincount(tokens[:, 0], minlength=256).float() / many
    assert (frequencies - probs).abs().sum() / 2 < 0.12  # total variation of 4000 draws over 256 bins


def test_a_token_of_zero_probability_is_never_drawn():
    model = make()
    with torch.no_grad():
        model.head.weight.mul_(1e4)  # every token but the likeliest underflows to probability 0
    obs, texts = observations(1)
    many = 500
    images, instructions = obs.expand(many, -1, -1, -1), texts * many
    probs = torch.softmax(model.logits(images[:1], texts).float(), dim=-1)
    assert (probs == 0).float().mean() > 0.9
    tokens = model.sample(images, instructions, 1.0, torch.Generator().manual_seed(0)).tokens
    assert torch.equal(tokens, model.logits(images, instructions).argmax(-1))


def test_higher_temperature_spreads_the_samples():
    model = make()
    with torch.no_grad():
        model.head.weight.mul_(30.0)  # a confident policy, so temperature has something to undo
    obs, texts = observations(1)
    many = 300
    spread = {}
    for temperature in (0.2, 3.0):
        tokens = model.sample(obs.expand(many, -1, -1, -1), texts * many, temperature, torch.Generator().manual_seed(0)).tokens
        spread[temperature] = tokens.float().std(0).mean().item()
    assert spread[3.0] > 2 * spread[0.2] + 1.0


def test_act_is_greedy_and_deterministic():
    model = make()
    obs, texts = observations()
    greedy = model.logits(obs, texts).argmax(-1)
    torch.testing.assert_close(model.act(obs, texts), model.tokenizer.decode(greedy.view(2, 3, 4)))


def test_seeded_sampling_is_reproducible():
    model = make()
    obs, texts = observations()
    first = model.sample(obs, texts, 1.6, torch.Generator().manual_seed(7)).tokens
    second = model.sample(obs, texts, 1.6, torch.Generator().manual_seed(7)).tokens
    assert torch.equal(first, second)


def test_saved_and_loaded_policy_gives_identical_outputs(tmp_path):
    model = make(seed=5)
    save_checkpoint(tmp_path, 1, model, {"model": model.spec()})
    loaded = load_policy(tmp_path)
    obs, texts = observations()
    torch.testing.assert_close(loaded.logits(obs, texts), model.logits(obs, texts))
    assert loaded.tokenizer == model.tokenizer and loaded.config == model.config


def test_wrong_image_shape_names_expected_and_actual():
    model = make()
    try:
        model.act(torch.zeros(1, 48, 48, 3, dtype=torch.uint8), ["x"])
    except ValueError as error:
        assert "32, 32, 3" in str(error) and "48, 48, 3" in str(error)
    else:
        raise AssertionError("a 48 px image was accepted by a 32 px policy")


def test_paraphrases_are_closer_than_unrelated_instructions():
    encoder = InstructionEncoder()
    a, b, c = encoder(["open the drawer", "pull the drawer open", "press the button from above"])
    assert torch.dot(a, b) > torch.dot(a, c)


def test_efficientnet_variant_builds_a_token_grid():
    model = make(config=VLAConfig(vision="efficientnet", width=32, layers=1, heads=2, chunk_size=2, image_size=32))
    obs, texts = observations()
    assert model.logits(obs, texts).shape == (2, 8, 256)


def test_an_instruction_embeds_identically_alone_and_among_others():
    alone = InstructionEncoder()(["open the drawer"])[0]
    among = InstructionEncoder()(["a much longer instruction that pads the batch", "open the drawer"])[1]
    assert torch.equal(alone, among)
