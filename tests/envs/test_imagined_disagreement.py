"""The imagined envs with a world-model ensemble: the disagreement they report, and the stop."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gymnast.envs.engine import run_batch
from gymnast.envs.imagined import BatchedImaginedEnv, ImaginedEnv
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.ensemble import EnsembleWorldModel

SIZE, ROLLOUTS, HORIZON = 32, 3, 12
TINY = EmbeddedWorldModelConfig(image_size=SIZE, latent_channels=16, widths=(8, 16), blocks=1, action_width=16, bf16=False)


def member(seed: int) -> EmbeddedWorldModel:
    torch.manual_seed(seed)
    model = EmbeddedWorldModel(TINY)
    for block in model.blocks:  # a fresh model's blocks are the identity; weights make members differ
        torch.nn.init.normal_(block.conv2.weight, std=0.2)
    return model.eval()


@pytest.fixture(scope="module")
def ensemble() -> EnsembleWorldModel:
    return EnsembleWorldModel([member(0), member(1)])


def start_options() -> dict:
    frames = np.random.default_rng(0).integers(0, 256, (ROLLOUTS, SIZE, SIZE, 3), dtype=np.uint8)
    return {"frames": frames, "instructions": ["reach"] * ROLLOUTS}


def plan() -> np.ndarray:
    """(steps, B, K, A) action chunks that cover the horizon (the last one is cut)."""
    return np.random.default_rng(1).uniform(-1, 1, (3, ROLLOUTS, 5, 4)).astype(np.float32)


def test_batched_env_reports_the_ensembles_own_disagreement(ensemble):
    env = BatchedImaginedEnv(ensemble, ROLLOUTS, horizon=HORIZON)
    options = start_options()
    env.reset(seed=0, options=options)
    state = ensemble.init_state(torch.from_numpy(options["frames"][:, None]))
    for chunk in plan():
        *_, info = env.step(chunk)
        state, _ = ensemble.step(state, torch.from_numpy(chunk[:, : info["frames"].shape[1]]))
        np.testing.assert_allclose(info["disagreement"], state.disagreement.numpy(), rtol=1e-5, atol=1e-6)
    assert info["disagreement"].shape == (ROLLOUTS, 2)  # the horizon cut the last chunk to 2 actions


def test_single_env_reports_its_rollouts_disagreement_and_a_single_model_none(ensemble):
    options = start_options()
    chunk = plan()[0]
    batched = BatchedImaginedEnv(ensemble, ROLLOUTS, horizon=HORIZON)
    batched.reset(seed=0, options=options)
    *_, batched_info = batched.step(chunk)
    single = ImaginedEnv(ensemble, horizon=HORIZON)
    single.reset(seed=0, options={"frames": options["frames"][0], "instruction": "reach"})
    *_, info = single.step(chunk[0])
    assert info["disagreement"].shape == (5,)
    np.testing.assert_allclose(info["disagreement"], batched_info["disagreement"][0], rtol=1e-3, atol=1e-4)
    alone = BatchedImaginedEnv(member(0), ROLLOUTS, horizon=HORIZON)
    alone.reset(seed=0, options=options)
    assert "disagreement" not in alone.step(chunk)[-1]


def _replay(env: BatchedImaginedEnv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(B, T) disagreement, (B,) actions executed and the (B, T + 1, ...) video of the plan in `env`."""
    chunks = iter(plan())
    results = list(run_batch(env, lambda images, instructions, states: next(chunks), start_options(), seed=0))
    executed = np.sum([r.executed for r in results], axis=0)
    return np.concatenate([r.disagreement for r in results], axis=1), executed, env.video()


def test_a_rollout_stops_before_its_first_frame_over_the_threshold(ensemble):
    disagreement, executed, video = _replay(BatchedImaginedEnv(ensemble, ROLLOUTS, horizon=HORIZON))
    assert (executed == HORIZON).all()
    threshold = float(np.quantile(disagreement, 0.5))
    over = disagreement > threshold  # (B, T)
    expected = np.where(over.any(axis=1), over.argmax(axis=1), HORIZON)  # (B,) frames shown before the first over
    assert (expected < HORIZON).any(), "the threshold should stop some rollout for the test to mean anything"

    stopping = BatchedImaginedEnv(ensemble, ROLLOUTS, horizon=HORIZON, stop_above=threshold)
    _, stopped_executed, stopped_video = _replay(stopping)
    np.testing.assert_array_equal(stopped_executed, expected)
    for b, shown in enumerate(expected):
        np.testing.assert_array_equal(stopped_video[b, : shown + 1], video[b, : shown + 1])  # the same until the stop
        assert (stopped_video[b, shown + 1:] == video[b, shown]).all()  # then its last trusted frame repeats


def test_stopping_needs_a_world_model_that_reports_disagreement():
    env = BatchedImaginedEnv(member(0), ROLLOUTS, horizon=HORIZON, stop_above=0.1)
    env.reset(seed=0, options=start_options())
    with pytest.raises(RuntimeError, match="ensemble"):
        env.step(plan()[0])
