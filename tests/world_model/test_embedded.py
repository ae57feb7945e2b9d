"""The embedded world model honours the WorldModel contract: shapes, seeding, chunking, saving, errors."""

import dataclasses

import numpy as np
import pytest
import torch

from gymnast.envs.engine import run_batch
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.utils.checkpoint import save_checkpoint
from gymnast.world_model.base import load_world_model, rollout
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig

TINY = EmbeddedWorldModelConfig(image_size=32, latent_channels=16, widths=(8, 16), blocks=1, action_width=16, bf16=False)


def make_model(seed: int = 0) -> EmbeddedWorldModel:
    torch.manual_seed(seed)
    model = EmbeddedWorldModel(TINY)
    # A fresh model's blocks are the identity (zero-initialised output convolutions), so it would
    # ignore its actions; give them weights, as training would.
    for block in model.blocks:
        torch.nn.init.normal_(block.conv2.weight, std=0.1)
    return model.eval()


def frames(batch: int, count: int, seed: int = 0) -> torch.Tensor:
    return torch.randint(0, 256, (batch, count, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))


def actions(batch: int, steps: int, seed: int = 1) -> torch.Tensor:
    return torch.rand(batch, steps, 4, generator=torch.Generator().manual_seed(seed)) * 2 - 1


def test_step_imagines_one_uint8_frame_per_action():
    model = make_model()
    state, imagined = model.step(model.init_state(frames(3, 2)), actions(3, 5))
    assert imagined.shape == (3, 5, 32, 32, 3) and imagined.dtype == torch.uint8
    assert state.z.shape[0] == 3


def test_a_single_start_frame_means_a_robot_standing_still():
    model = make_model()
    one = frames(2, 1)
    assert torch.equal(model.init_state(one).z, model.init_state(torch.cat([one, one], dim=1)).z)


def test_more_context_than_needed_uses_the_most_recent_frames():
    model = make_model()
    context = frames(2, 4)
    assert torch.equal(model.init_state(context).z, model.init_state(context[:, -2:]).z)


def test_same_seed_and_inputs_give_identical_frames():
    a = make_model(seed=3).step(make_model(seed=3).init_state(frames(2, 2)), actions(2, 6))[1]
    model = make_model(seed=3)
    b = model.step(model.init_state(frames(2, 2)), actions(2, 6))[1]
    assert torch.equal(a, b)


def test_different_actions_imagine_different_futures():
    model = make_model()
    state = model.init_state(frames(1, 2))
    assert not torch.equal(model.step(state, actions(1, 4, seed=1))[1], model.step(state, actions(1, 4, seed=2))[1])


def test_stepping_in_chunks_equals_one_long_step():
    model = make_model()
    state = model.init_state(frames(2, 2))
    whole = model.step(state, actions(2, 6))[1]
    middle, first = model.step(state, actions(2, 6)[:, :3])
    second = model.step(middle, actions(2, 6)[:, 3:])[1]
    assert torch.equal(whole, torch.cat([first, second], dim=1))


def test_checkpoint_round_trip_gives_the_same_model(tmp_path):
    model = make_model()
    save_checkpoint(tmp_path, 1, model, {"model": model.spec()})
    loaded = load_world_model(tmp_path)
    assert loaded.config == model.config
    context, moves = frames(2, 2), actions(2, 5)
    assert torch.equal(model.step(model.init_state(context), moves)[1], loaded.step(loaded.init_state(context), moves)[1])


def test_unknown_backend_is_a_clear_error(tmp_path):
    model = make_model()
    save_checkpoint(tmp_path, 1, model, {"model": {**model.spec(), "backend": "nope"}})
    with pytest.raises(ValueError, match="backend is 'nope'"):
        load_world_model(tmp_path)


@pytest.mark.parametrize(
    "context, match",
    [
        (torch.zeros(1, 2, 48, 32, 3, dtype=torch.uint8), r"\(B, C, 32, 32, 3\) uint8, got \(1, 2, 48, 32, 3\)"),
        (torch.zeros(1, 2, 32, 32, 4, dtype=torch.uint8), r"\(B, C, 32, 32, 3\) uint8, got \(1, 2, 32, 32, 4\)"),
        (torch.zeros(1, 2, 32, 32, 3), r"got dtype torch.float32"),
        (torch.zeros(2, 32, 32, 3, dtype=torch.uint8), r"got \(2, 32, 32, 3\)"),
    ],
)
def test_bad_frames_raise_value_errors_naming_the_shapes(context, match):
    with pytest.raises(ValueError, match=match):
        make_model().init_state(context)


@pytest.mark.parametrize("bad", [torch.zeros(2, 3, 7), torch.zeros(3, 3, 4), torch.zeros(2, 4), torch.zeros(2, 3, 4, dtype=torch.int64)])
def test_bad_actions_raise_value_errors_naming_the_shapes(bad):
    model = make_model()
    with pytest.raises(ValueError, match=r"\(2, K, 4\) float, got"):
        model.step(model.init_state(frames(2, 1)), bad)


def test_a_closed_loop_rollout_stepped_by_the_engine_equals_the_open_loop_rollout_of_its_actions():
    model = make_model()
    plan = actions(2, 7).numpy()
    chunks = iter([plan[:, 0:3], plan[:, 3:6], np.concatenate([plan[:, 6:], np.zeros((2, 2, 4), np.float32)], 1)])
    seen = []

    def actor(images: np.ndarray, instructions: list[str], states: None) -> np.ndarray:
        seen.append(images.shape)
        return next(chunks)

    start = {"frames": frames(2, 1).numpy(), "instructions": ["a", "b"]}
    results = list(run_batch(BatchedImaginedEnv(model, 2, chunk_size=3, horizon=7), actor, start))
    closed = np.concatenate([result.frames for result in results], axis=1)
    fixed = rollout(model, frames(2, 1), actions=torch.from_numpy(plan))
    assert np.array_equal(closed, fixed.frames.numpy()) and torch.equal(fixed.actions, torch.from_numpy(plan))
    assert seen == [(2, 32, 32, 3)] * 3  # chunks of 3, 3 and the last one cut to 1 at the horizon


def test_long_rollouts_re_anchor_on_their_own_frames_at_the_trained_horizon():
    model = make_model()
    anchored = EmbeddedWorldModel(dataclasses.replace(TINY, reanchor_every=3)).eval()
    anchored.load_state_dict(model.state_dict())
    never = EmbeddedWorldModel(dataclasses.replace(TINY, reanchor_every=0)).eval()
    never.load_state_dict(model.state_dict())
    context, moves = frames(2, 2), actions(2, 7)
    a = anchored.step(anchored.init_state(context), moves)[1]
    b = never.step(never.init_state(context), moves)[1]
    assert torch.equal(a[:, :3], b[:, :3]) and not torch.equal(a[:, 3:], b[:, 3:])
    middle, first = anchored.step(anchored.init_state(context), moves[:, :2])  # re-anchoring spans step calls
    assert torch.equal(torch.cat([first, anchored.step(middle, moves[:, 2:])[1]], dim=1), a)
