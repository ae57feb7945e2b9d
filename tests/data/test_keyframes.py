"""Keyframe starts: drawn where the setting says, and restored exactly in the real world by
replaying the actions that led there."""

from __future__ import annotations

import numpy as np
import pytest

from gymnast.config import EnvConfig
from gymnast.data.keyframes import KeyframeConfig, dataset_keyframes, keyframe_indices, keyframe_start
from gymnast.data.lerobot import EpisodeDataset
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.envs.starts import start_options


def _episode(dataset: EpisodeDataset, success: bool):
    return next(dataset.load(i) for i, info in enumerate(dataset.episodes) if info.success == success)


def test_a_keyframe_is_restored_exactly_by_replaying_its_prefix(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    episode = _episode(dataset, success=True)
    t = len(episode.actions) // 2
    start = keyframe_start(episode, t, KeyframeConfig(horizon=8))
    env = MetaWorldEnv(start.task, config=EnvConfig(image_size=32, horizon=100))
    try:
        obs, info = env.reset(seed=start.seed, options={"prefix": start.prefix})
        assert info["prefix_steps"] == t and info["step"] == 0
        np.testing.assert_allclose(info["env_state"], episode.env_states[t], atol=1e-5)
        np.testing.assert_allclose(start.state, episode.env_states[t])
        # The recording goes on from there as it went on then.
        for k, action in enumerate(start.reference_actions):
            env.step(action)
            np.testing.assert_allclose(env.env_state, episode.env_states[t + k + 1], atol=1e-4)
    finally:
        env.close()


def test_the_vector_env_starts_each_episode_at_its_keyframe_and_counts_the_horizon_from_there(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    episode = _episode(dataset, success=False)
    starts = [keyframe_start(episode, t, KeyframeConfig(horizon=4)) for t in (0, 5)]
    env = SimVectorEnv(2, chunk_size=4, config=EnvConfig(image_size=32, horizon=4, terminate_on_success=False))
    try:
        _, infos = env.reset(options=start_options(starts))
        assert infos["prefix_steps"].tolist() == [0, 5]
        _, _, _, truncated, infos = env.step(np.stack([s.reference_actions for s in starts]))
        assert truncated.all() and infos["step"].tolist() == [4, 4]
    finally:
        env.close()


def test_a_prefix_of_the_wrong_shape_is_refused_naming_it():
    env = MetaWorldEnv("reach-v3", config=EnvConfig(image_size=32))
    try:
        with pytest.raises(ValueError, match=r"\(T0, 4\).*\(3,\)"):
            env.reset(seed=1, options={"prefix": np.zeros(3)})
    finally:
        env.close()


def test_keyframes_are_drawn_where_the_sampling_says(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    won, lost = _episode(dataset, success=True), _episode(dataset, success=False)
    rng = np.random.default_rng(0)
    assert keyframe_indices(won, KeyframeConfig(sampling="first", per_episode=3), rng) == [0, 0, 0]
    first_success = int(np.argmax(won.successes)) + 1
    near = keyframe_indices(won, KeyframeConfig(sampling="near_success", horizon=5, per_episode=20), rng)
    assert all(max(0, first_success - 5) <= t < first_success for t in near)
    assert keyframe_indices(won, KeyframeConfig(sampling="failures"), rng) == []
    anywhere = keyframe_indices(lost, KeyframeConfig(sampling="uniform", per_episode=50), rng)
    assert all(0 <= t < len(lost.actions) for t in anywhere) and len(set(anywhere)) > 1


def test_every_keyframe_start_has_the_same_context_length_with_the_first_frame_repeated(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    config = KeyframeConfig(sampling="uniform", per_episode=3, context_frames=3, horizon=6)
    starts = dataset_keyframes(dataset, range(len(dataset)), config)
    assert {s.frames.shape[0] for s in starts} == {3}
    episode = dataset.load(0)
    first = keyframe_start(episode, 0, config)
    assert (first.frames == episode.frames[0]).all() and len(first.prefix) == 0
    assert all(len(s.reference_actions) <= 6 for s in starts)


@pytest.mark.parametrize("sampling", ["uniform", "near_success", "failures"])
def test_dataset_keyframes_decode_only_their_context_and_equal_starts_made_from_whole_episodes(tiny_dataset, sampling):
    dataset = EpisodeDataset(tiny_dataset)
    config = KeyframeConfig(sampling=sampling, per_episode=2, context_frames=3, horizon=5)
    starts = dataset_keyframes(dataset, range(len(dataset)), config, seed=3)
    rng, expected = np.random.default_rng(3), []
    for i in range(len(dataset)):
        episode = dataset.load(i)
        expected += [keyframe_start(episode, t, config) for t in keyframe_indices(episode, config, rng)]
    assert len(starts) == len(expected) > 0
    for start, whole in zip(starts, expected, strict=True):
        assert (start.task, start.seed, start.instruction) == (whole.task, whole.seed, whole.instruction)
        for field in ("frames", "reference_actions", "prefix", "state"):
            np.testing.assert_array_equal(getattr(start, field), getattr(whole, field))


def test_an_unknown_sampling_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="near_success"):
        KeyframeConfig(sampling="middle")
