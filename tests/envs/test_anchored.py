"""The anchored env: real rollouts, seen through a world model restarted from the real frame."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL before Meta-World imports mujoco)
from gymnast.config import EnvConfig
from gymnast.envs.anchored import AnchoredImaginedEnv
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.factory import EnvFactory
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.envs.kinds import ANCHORED
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig

K, SIZE = 5, 32
HORIZON = 42  # reach-v3's expert succeeds on seed 3 before it, mid-chunk
CONFIG = EnvConfig(image_size=SIZE, horizon=HORIZON)
TINY = EmbeddedWorldModelConfig(image_size=SIZE, latent_channels=8, widths=(8, 16), blocks=1, action_width=8, bf16=False)
SEEDS = [3, 3]


@pytest.fixture(scope="module")
def model() -> EmbeddedWorldModel:
    torch.manual_seed(0)
    model = EmbeddedWorldModel(TINY).eval()
    for block in model.blocks:  # random last convs, so that actions show in the frames
        torch.nn.init.normal_(block.conv2.weight, std=0.2)
    return model


@pytest.fixture(scope="module")
def chunks() -> np.ndarray:
    """(S, 2, K, A): rollout 0 the expert's successful episode on reach-v3 seed 3, then zeros;
    rollout 1 random actions, which do not succeed."""
    plain = MetaWorldEnv("reach-v3", CONFIG)
    expert = ScriptedExpert("reach-v3")
    _, info = plain.reset(seed=3)
    actions, terminated = [], False
    while not terminated:
        actions.append(expert(info["env_state"]))
        _, _, terminated, _, info = plain.step(actions[-1])
    plain.close()
    steps = -(-HORIZON // K)
    result = np.random.default_rng(0).uniform(-1, 1, size=(steps, 2, K, 4)).astype(np.float32)
    padded = np.zeros((steps * K, 4), np.float32)
    padded[: len(actions)] = actions
    result[:, 0] = padded.reshape(steps, K, 4)
    return result


def options(first_frames: np.ndarray) -> dict:
    return {"tasks": ["reach-v3"] * 2, "seeds": SEEDS, "frames": first_frames, "instructions": ["reach"] * 2}


def first_frames() -> np.ndarray:
    with SimVectorEnv(2, K, CONFIG) as real:
        obs, _ = real.reset(options={"tasks": ["reach-v3"] * 2, "seeds": SEEDS})
    return obs["image"]


def play(env, chunks: np.ndarray, reset: dict) -> list:
    outputs = [env.reset(seed=0, options=reset)]
    for chunk in chunks:
        outputs.append(env.step(chunk))
    return outputs


def test_the_rollouts_are_the_real_worlds_and_the_frames_the_world_models(model, chunks):
    start = first_frames()
    with SimVectorEnv(2, K, CONFIG) as real:
        truth = play(real, chunks, options(start))
    anchored = AnchoredImaginedEnv(BatchedImaginedEnv(model, 2, K, HORIZON), SimVectorEnv(2, K, CONFIG), every=2 * K)
    seen = play(anchored, chunks, options(start))
    anchored.close()
    for (_, reward, terminated, truncated, info), (_, real_reward, real_end, real_cut, real_info) in zip(seen[1:], truth[1:]):
        np.testing.assert_array_equal(reward, real_reward)
        np.testing.assert_array_equal(terminated, real_end)
        np.testing.assert_array_equal(truncated, real_cut)
        for key in ("success", "executed", "step"):
            np.testing.assert_array_equal(info[key], real_info[key])
    assert seen[-1][4]["success"].tolist() == [True, False]  # the expert succeeded, for real
    # Every second chunk ends on the real frame the actions reached; the frames between are imagined.
    for index, ((obs, *_, info), (real_obs, *_, real_info)) in enumerate(zip(seen[1:], truth[1:]), start=1):
        running = real_info["executed"] == K
        if not running.any():  # the last chunk, cut at the horizon
            continue
        if index % 2 == 0:
            np.testing.assert_array_equal(obs["image"][running], real_obs["image"][running])
        else:
            assert not np.array_equal(obs["image"][running], real_obs["image"][running])
        np.testing.assert_array_equal(obs["image"], info["frames"][:, -1])


def test_after_a_restart_it_imagines_what_the_model_imagines_from_the_real_frame(model, chunks):
    start = first_frames()
    with SimVectorEnv(2, K, CONFIG) as real:
        real.reset(options=options(start))
        for chunk in chunks[:2]:
            reached, *_ = real.step(chunk)
    anchored = AnchoredImaginedEnv(BatchedImaginedEnv(model, 2, K, HORIZON), SimVectorEnv(2, K, CONFIG), every=2 * K)
    seen = play(anchored, chunks[:3], options(start))
    anchored.close()
    fresh = BatchedImaginedEnv(model, 2, K, HORIZON)
    fresh.reset(seed=0, options={"frames": reached["image"], "instructions": ["reach"] * 2})
    _, _, _, _, continued = fresh.step(chunks[2])
    np.testing.assert_allclose(seen[3][4]["frames"][1].astype(int), continued["frames"][1].astype(int), atol=1)


def test_an_ended_rollout_holds_its_last_frame(model, chunks):
    anchored = AnchoredImaginedEnv(BatchedImaginedEnv(model, 2, K, HORIZON), SimVectorEnv(2, K, CONFIG), every=K)
    seen = play(anchored, chunks, options(first_frames()))
    anchored.close()
    ended = next(i for i, step in enumerate(seen[1:], start=1) if step[2][0])  # the expert's success
    executed = seen[ended][4]["executed"][0]
    frames = seen[ended][4]["frames"][0]
    assert (frames[executed:] == frames[executed - 1]).all()
    for step in seen[ended + 1:]:
        assert (step[4]["frames"][0] == frames[-1]).all() and step[4]["executed"][0] == 0


def test_it_restarts_between_chunks_only(model):
    with pytest.raises(ValueError, match="multiple of the policy's chunk of 5 actions, got 7"):
        AnchoredImaginedEnv(BatchedImaginedEnv(model, 2, K, HORIZON), SimVectorEnv(2, K, CONFIG), every=7)
    with pytest.raises(ValueError, match="the same rollouts and chunks"):
        AnchoredImaginedEnv(BatchedImaginedEnv(model, 3, K, HORIZON), SimVectorEnv(2, K, CONFIG), every=K)


def test_the_factory_builds_it_for_the_anchored_kind(model):
    factory = EnvFactory(ANCHORED, K, CONFIG, "mild", 1, model, anchor_every=3 * K)
    env = factory.get(ANCHORED, 2)
    assert isinstance(env, AnchoredImaginedEnv) and env.every == 3 * K
    assert env.real.num_envs == env.imagined.num_envs == 2
    factory.close()
