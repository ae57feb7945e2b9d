"""The world model's action input normalised by the dataset's range; checkpoints saved before it behave as they did."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from gymnast.world_model.base import load_world_model
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.flow import FlowWorldModel, FlowWorldModelConfig

COMMITTED = Path(__file__).resolve().parents[2] / "results" / "world_model" / "wm"
TINY = EmbeddedWorldModelConfig(image_size=32, action_dim=3, latent_channels=16, widths=(8, 16), blocks=1,
                                action_width=16, bf16=False)
TINY_FLOW = FlowWorldModelConfig(image_size=32, action_dim=3, latent_channels=4, widths=(8, 16), width=16, blocks=1,
                                 condition_width=16, sample_steps=2, bf16=False)
RANGE = dict(action_low=(-4.0, 0.0, 10.0), action_high=(4.0, 2.0, 20.0))


def _weighted(model):
    for block in model.blocks:  # a fresh model's blocks ignore the action; give them weights, as training would
        torch.nn.init.normal_(block.conv2.weight, std=0.1)
    return model.eval()


def _imagine(model, actions: torch.Tensor) -> torch.Tensor:
    size = model.image_size
    context = torch.randint(0, 256, (2, 2, size, size, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    return model.step(model.init_state(context), actions, torch.Generator().manual_seed(3))[1]


@pytest.mark.parametrize("backend, tiny", [(EmbeddedWorldModel, TINY), (FlowWorldModel, TINY_FLOW)], ids=["embedded", "flow"])
def test_actions_are_mapped_from_the_datasets_range_onto_minus_one_to_one(backend, tiny):
    torch.manual_seed(0)
    plain = _weighted(backend(tiny))
    ranged = backend(dataclasses.replace(tiny, **RANGE))
    ranged.load_state_dict(plain.state_dict())
    assert ranged.action_range == (RANGE["action_low"], RANGE["action_high"])
    unit = torch.rand(2, 5, 3, generator=torch.Generator().manual_seed(1)) * 2 - 1
    raw = unit * torch.tensor([4.0, 1.0, 5.0]) + torch.tensor([0.0, 1.0, 15.0])
    torch.testing.assert_close(_imagine(ranged, raw), _imagine(plain, unit), atol=1, rtol=0)  # uint8: a rounding apart


def test_a_range_of_the_wrong_width_is_refused():
    for tiny in (TINY, TINY_FLOW):
        with pytest.raises(ValueError, match="action_low and action_high need 3 values each"):
            dataclasses.replace(tiny, action_low=(-1.0,), action_high=(1.0,))


@pytest.mark.skipif(not COMMITTED.exists(), reason="the committed world model is not in this checkout")
def test_a_checkpoint_saved_before_the_range_loads_and_imagines_as_before():
    old = load_world_model(COMMITTED)
    assert old.config.action_low == () and old.action_dim == 4
    # Meta-World's range is [-1, 1]: a model trained today gets it, and it changes nothing.
    new = EmbeddedWorldModel(dataclasses.replace(old.config, action_low=(-1.0,) * 4, action_high=(1.0,) * 4))
    new.load_state_dict(old.state_dict())
    actions = torch.rand(2, 4, 4, generator=torch.Generator().manual_seed(2)) * 2 - 1
    assert torch.equal(_imagine(new.eval(), actions), _imagine(old, actions))


def test_the_imagined_env_acts_in_the_world_models_range():
    from gymnast.envs.imagined import BatchedImaginedEnv

    torch.manual_seed(0)
    plain = _weighted(EmbeddedWorldModel(TINY))
    ranged = EmbeddedWorldModel(dataclasses.replace(TINY, action_low=(-4.0, 0.0, 10.0), action_high=(4.0, 2.0, 20.0)))
    ranged.load_state_dict(plain.state_dict())
    env = BatchedImaginedEnv(ranged.eval(), 1, chunk_size=2, horizon=4)
    assert env.single_action_space.low[0].tolist() == [-4.0, 0.0, 10.0]
    assert env.single_action_space.high[1].tolist() == [4.0, 2.0, 20.0]
    start = torch.zeros(1, 1, 32, 32, 3, dtype=torch.uint8)
    env.reset(options={"frames": start.numpy(), "instructions": ["pick up the cube"]})
    beyond = np.array([[[9.0, 3.0, 25.0], [-9.0, -1.0, 0.0]]], np.float32)  # (1, K, A), outside the range
    frames = env.step(beyond)[0]["image"]
    clipped = torch.tensor([[[4.0, 2.0, 20.0], [-4.0, 0.0, 10.0]]])
    expected = ranged.step(ranged.init_state(start), clipped)[1][0, -1]
    assert torch.equal(torch.from_numpy(frames[0]), expected)


@pytest.mark.skipif(not COMMITTED.exists(), reason="the committed world model is not in this checkout")
def test_a_checkpoint_saved_before_the_range_can_be_fine_tuned():
    from gymnast.world_model.train import WM_PRESETS, build_model

    old = load_world_model(COMMITTED)
    from_data = dataclasses.replace(old.config, action_low=(-0.9,) * 4, action_high=(0.9,) * 4)  # what fit_to_data sets
    model = build_model(dataclasses.replace(WM_PRESETS["full"], init=COMMITTED, model=from_data))
    assert model.config.action_low == () and model.action_range == ((-1.0,) * 4, (1.0,) * 4)  # the weights' own
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), old.state_dict().values()))
