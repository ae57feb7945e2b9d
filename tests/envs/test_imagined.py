"""The imagined env: the Gymnasium contract, real start frames, determinism, the horizon, batching."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import gymnast  # noqa: F401  (sets MUJOCO_GL before Meta-World imports mujoco)
from gymnast.envs.imagined import BatchedImaginedEnv, ImaginedEnv
from gymnast.envs.starts import Start
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig

SIZE = 96
# float32 so that batched and single rollouts agree to rounding (bf16 would differ more).
TINY = EmbeddedWorldModelConfig(image_size=SIZE, latent_channels=16, widths=(8, 16), blocks=1, action_width=16, bf16=False)


@pytest.fixture(scope="module")
def starts() -> list[Start]:
    """Real camera frames and instructions from the simulator (slow to build, so built once)."""
    env = MetaWorldEnv("reach-v3")
    result = []
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        result.append(Start("reach-v3", seed, info["instruction"], obs["image"][None].copy()))
    env.close()
    return result


@pytest.fixture(scope="module")
def model() -> EmbeddedWorldModel:
    torch.manual_seed(0)
    model = EmbeddedWorldModel(TINY).eval()
    # Untrained residual blocks start as the identity (zero last conv), so the frames would ignore
    # the actions; random weights there make every action show in the frames.
    for block in model.blocks:
        torch.nn.init.normal_(block.conv2.weight, std=0.2)
    return model


def chunks(seed: int, n: int, shape: tuple[int, ...] = (5, 4)) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, size=(n, *shape)).astype(np.float32)


def play(env: ImaginedEnv, actions: np.ndarray, **reset) -> np.ndarray:
    env.reset(**reset)
    for chunk in actions:
        env.step(chunk)
    return env.video()


def test_passes_gymnasium_check_env_in_every_render_mode(model, starts):
    spec = gym.envs.registration.EnvSpec("Imagined-test-v0", entry_point=ImaginedEnv, kwargs={"model": model, "starts": starts})
    env = gym.make(spec, render_mode="rgb_array")
    check_env(env.unwrapped, skip_render_check=False)
    assert env.unwrapped.metadata["render_fps"] == 80 / 5  # one rendered frame per chunk of 5 actions


def test_reset_with_options_starts_from_exactly_the_given_frame(model, starts):
    env = ImaginedEnv(model)
    frames = np.stack([starts[0].frames[-1], starts[1].frames[-1]])  # (C=2, H, W, 3): last one is now
    obs, info = env.reset(options={"frames": frames, "instruction": "reach the goal"})
    np.testing.assert_array_equal(obs["image"], starts[1].frames[-1])
    assert info == {"instruction": "reach the goal", "step": 0}
    obs, _ = env.reset(options={"frames": starts[2].frames[-1], "instruction": "x"})  # (H, W, 3) too
    np.testing.assert_array_equal(obs["image"], starts[2].frames[-1])
    np.testing.assert_array_equal(env.video(), starts[2].frames[-1:])


def test_reset_without_options_draws_one_of_the_starts_with_the_seed(model, starts):
    env = ImaginedEnv(model, starts=starts)
    drawn = {}
    for seed in range(12):
        obs, info = env.reset(seed=seed)
        index = next(i for i, s in enumerate(starts) if np.array_equal(s.frames[-1], obs["image"]))
        assert info["instruction"] == starts[index].instruction
        assert env.reset(seed=seed)[0]["image"].tobytes() == obs["image"].tobytes()
        drawn[seed] = index
    assert len(set(drawn.values())) > 1


def test_same_seed_and_actions_give_identical_frames(model, starts):
    actions = chunks(0, 4)
    first = play(ImaginedEnv(model, starts=starts), actions, seed=3)
    second = play(ImaginedEnv(model, starts=starts), actions, seed=3)
    assert first.shape == (1 + 4 * 5, SIZE, SIZE, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, second)


def test_different_action_chunks_give_different_frames(model, starts):
    env = ImaginedEnv(model, starts=starts)
    first = play(env, chunks(0, 2), seed=3)
    second = play(env, chunks(1, 2), seed=3)
    np.testing.assert_array_equal(first[0], second[0])  # the same real start frame
    assert (first[1:] != second[1:]).any(axis=(1, 2, 3)).all()  # every imagined frame differs


def test_actions_outside_the_box_are_clipped(model, starts):
    env = ImaginedEnv(model, starts=starts)
    actions = chunks(0, 2)
    np.testing.assert_array_equal(play(env, actions * 3, seed=0), play(env, np.clip(actions * 3, -1, 1), seed=0))


def test_truncates_exactly_at_the_horizon_with_horizon_frames(model, starts):
    env = ImaginedEnv(model, starts=starts, chunk_size=4, horizon=10, render_mode="rgb_array")
    env.reset(seed=0)
    results = [env.step(chunk) for chunk in chunks(0, 3, (4, 4))]
    assert [info["step"] for *_, info in results] == [4, 8, 10]
    assert [info["frames"].shape[0] for *_, info in results] == [4, 4, 2]  # the last chunk is cut
    assert [truncated for _, _, _, truncated, _ in results] == [False, False, True]
    assert all(reward == 0.0 and terminated is False for _, reward, terminated, _, _ in results)
    video = env.video()
    assert video.shape == (11, SIZE, SIZE, 3)
    np.testing.assert_array_equal(video[1:], np.concatenate([info["frames"] for *_, info in results]))
    np.testing.assert_array_equal(results[-1][0]["image"], video[-1])
    np.testing.assert_array_equal(env.render(), video[-1])
    with pytest.raises(RuntimeError, match="horizon"):
        env.step(np.zeros((4, 4), np.float32))
    env.reset(seed=0)
    assert env.video().shape == (1, SIZE, SIZE, 3)
    assert env.step(np.zeros((4, 4), np.float32))[4]["step"] == 4


def test_step_before_reset_raises(model, starts):
    with pytest.raises(RuntimeError, match="reset"):
        ImaginedEnv(model, starts=starts).step(np.zeros((5, 4), np.float32))


@pytest.mark.parametrize(
    "frames",
    [
        np.zeros((64, 64, 3), np.uint8),  # wrong size
        np.zeros((SIZE, SIZE, 4), np.uint8),  # wrong channels
        np.zeros((SIZE, SIZE, 3), np.float32),  # float instead of uint8
        np.zeros((2, 1, SIZE, SIZE, 3), np.uint8),  # a batch given to the single env
    ],
    ids=["size", "channels", "dtype", "batch"],
)
def test_bad_start_frames_raise_value_error_naming_the_shapes(model, frames):
    expected = f"({SIZE}, {SIZE}, 3) or (C, {SIZE}, {SIZE}, 3) uint8"
    actual = f"{frames.shape} {frames.dtype}"
    with pytest.raises(ValueError) as error:
        ImaginedEnv(model).reset(options={"frames": frames, "instruction": "x"})
    assert expected in str(error.value) and actual in str(error.value)
    with pytest.raises(ValueError, match="uint8"):
        ImaginedEnv(model, starts=[Start("reach-v3", 0, "x", frames)])  # caught when the env is built


@pytest.mark.parametrize("shape", [(4,), (4, 5), (5, 3), (1, 5, 4)])
def test_bad_action_shapes_raise_value_error_naming_the_shapes(model, starts, shape):
    env = ImaginedEnv(model, starts=starts)
    env.reset(seed=0)
    with pytest.raises(ValueError) as error:
        env.step(np.zeros(shape, np.float32))
    assert "(5, 4)" in str(error.value) and str(shape) in str(error.value)


def test_reset_needs_a_real_start_frame_and_instruction(model, starts):
    with pytest.raises(ValueError, match="real start frame and instruction"):
        ImaginedEnv(model).reset(seed=0)
    with pytest.raises(ValueError, match="instruction"):
        ImaginedEnv(model, starts=starts).reset(options={"frames": starts[0].frames})


def test_batched_env_gives_the_frames_of_separate_envs(model, starts):
    frames = np.stack([s.frames for s in starts])  # (B=3, C=1, H, W, 3)
    instructions = [s.instruction for s in starts]
    batched = BatchedImaginedEnv(model, num_envs=3)
    assert batched.observation_space["image"].shape == (3, SIZE, SIZE, 3)
    assert batched.action_space.shape == (3, 5, 4)
    assert batched.metadata["autoreset_mode"] == AutoresetMode.DISABLED
    obs, info = batched.reset(seed=0, options={"frames": frames, "instructions": instructions})
    np.testing.assert_array_equal(obs["image"], frames[:, -1])
    assert list(info["instruction"]) == instructions
    actions = chunks(0, 3, (3, 5, 4))  # (steps, B, K, A)
    for chunk in actions:
        obs, rewards, terminated, truncated, info = batched.step(chunk)
        assert info["frames"].shape == (3, 5, SIZE, SIZE, 3)
        np.testing.assert_array_equal(obs["image"], info["frames"][:, -1])
    assert rewards.shape == (3,) and not rewards.any() and not terminated.any() and not truncated.any()
    for b, start in enumerate(starts):
        single = play(ImaginedEnv(model), actions[:, b], options={"frames": start.frames, "instruction": "x"})
        difference = np.abs(batched.video()[b].astype(int) - single)
        # Convolutions over a batch may sum in another order, and a value near x.5 then rounds to
        # the other uint8 level; anything more would be a real difference.
        assert difference.max() <= 1 and (difference > 0).mean() < 1e-3


def test_batched_env_truncates_together_and_needs_a_reset_to_go_on(model, starts):
    env = BatchedImaginedEnv(model, num_envs=3, horizon=7)
    options = {"frames": np.stack([s.frames[-1] for s in starts]), "instructions": ["a", "b", "c"]}
    env.reset(options=options)
    _, _, _, truncated, info = env.step(chunks(0, 1, (3, 5, 4))[0])
    assert not truncated.any() and list(info["step"]) == [5, 5, 5]
    _, _, terminated, truncated, info = env.step(chunks(1, 1, (3, 5, 4))[0])
    assert truncated.all() and not terminated.any() and info["frames"].shape[1] == 2
    assert env.video().shape == (3, 8, SIZE, SIZE, 3)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((3, 5, 4), np.float32))
    env.reset(options=options)
    assert env.video().shape == (3, 1, SIZE, SIZE, 3)


def test_batched_env_rejects_missing_or_misshapen_starts_and_actions(model, starts):
    env = BatchedImaginedEnv(model, num_envs=3)
    with pytest.raises(ValueError, match="real start frames and instructions"):
        env.reset(seed=0)
    with pytest.raises(ValueError) as error:
        env.reset(options={"frames": np.zeros((2, SIZE, SIZE, 3), np.uint8), "instructions": ["a", "b"]})
    assert f"(3, {SIZE}, {SIZE}, 3)" in str(error.value) and f"(2, {SIZE}, {SIZE}, 3)" in str(error.value)
    frames = np.stack([s.frames for s in starts])
    with pytest.raises(ValueError, match="3 strings"):
        env.reset(options={"frames": frames, "instructions": ["a", "b"]})
    env.reset(options={"frames": frames, "instructions": ["a", "b", "c"]})
    with pytest.raises(ValueError) as error:
        env.step(np.zeros((5, 4), np.float32))
    assert "(3, 5, 4)" in str(error.value) and "(5, 4)" in str(error.value)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_frames_from_a_gpu_come_back_exact_and_each_step_in_its_own_array():
    from gymnast.envs.imagined import HostCopier

    copy = HostCopier()
    first = torch.randint(0, 256, (4, 5, 8, 8, 3), dtype=torch.uint8, device="cuda")
    second = torch.randint(0, 256, (4, 5, 8, 8, 3), dtype=torch.uint8, device="cuda")
    kept = [copy(first), copy(second), copy(second[:, :2])]  # the last: a chunk cut at the horizon
    assert np.array_equal(kept[0], first.cpu().numpy()) and np.array_equal(kept[1], second.cpu().numpy())
    assert np.array_equal(kept[2], second[:, :2].cpu().numpy())
    assert not np.shares_memory(kept[0], kept[1])  # the reused buffer never backs a returned array
