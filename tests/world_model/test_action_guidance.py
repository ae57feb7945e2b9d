"""Action dropout and guidance in the embedded world model: what the actions change, scaled."""

import pytest
import torch

from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig

TINY = dict(image_size=16, latent_channels=8, widths=(8, 8), blocks=1, action_width=8, bf16=False)


def model(**settings) -> EmbeddedWorldModel:
    torch.manual_seed(0)
    built = EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY, **settings)).eval()
    with torch.no_grad():  # trained blocks respond to the action; fresh ones start as the identity
        for block in built.blocks:
            block.conv2.weight.normal_(0, 0.3)
        if built.no_action is not None:
            built.no_action.normal_()
    return built


def imagine(world_model: EmbeddedWorldModel, actions: torch.Tensor) -> torch.Tensor:
    context = torch.randint(0, 256, (2, 2, 16, 16, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    return world_model.step(world_model.init_state(context), actions)[1].float()


def with_guidance(trained: EmbeddedWorldModel, guidance: float) -> EmbeddedWorldModel:
    guided = EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY, action_dropout=0.1, guidance=guidance)).eval()
    guided.load_state_dict(trained.state_dict())
    return guided


def test_guidance_needs_a_model_trained_with_action_dropout_which_alone_has_the_no_action_step():
    assert model().no_action is None and model(action_dropout=0.1).no_action is not None
    with pytest.raises(ValueError, match="guidance 2.0 needs a model trained with action_dropout"):
        EmbeddedWorldModelConfig(**TINY, guidance=2.0)
    with pytest.raises(ValueError, match=r"action_dropout must be in \[0, 1\)"):
        EmbeddedWorldModelConfig(**TINY, action_dropout=1.0)


def test_guidance_one_is_the_actions_own_step_and_zero_ignores_the_actions():
    trained = model(action_dropout=0.1)
    actions = torch.rand(2, 3, 4) * 2 - 1
    other = torch.rand(2, 3, 4) * 2 - 1
    assert not torch.equal(imagine(trained, actions), imagine(trained, other))
    assert torch.equal(imagine(with_guidance(trained, 1.0), actions), imagine(trained, actions))
    unguided = with_guidance(trained, 0.0)  # the "no action" step alone
    assert torch.equal(imagine(unguided, actions), imagine(unguided, other))


def test_guidance_above_one_moves_the_frames_further_from_the_no_action_rollout():
    trained = model(action_dropout=0.1)
    actions = torch.rand(2, 3, 4) * 2 - 1
    free, plain, strong = (imagine(with_guidance(trained, w), actions) for w in (0.0, 1.0, 3.0))
    assert (strong - free).abs().mean() > (plain - free).abs().mean() > 0


def test_in_training_a_step_sees_the_no_action_embedding_in_about_action_dropout_of_the_steps():
    trained = model(action_dropout=0.5).train()
    z, condition = torch.randn(400, 8, 2, 2), trained.embed_action(torch.rand(400, 4) * 2 - 1)
    hidden = trained._blocks(z, trained.no_action.expand_as(condition))
    torch.manual_seed(3)
    stepped = trained._latent_step(z, condition)
    share = torch.isclose(stepped, hidden).flatten(1).all(1).float().mean().item()
    assert 0.4 < share < 0.6
