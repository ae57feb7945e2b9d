"""The envs are registered with Gymnasium: tools that build envs by id get gymnast's envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from gymnast.config import EnvConfig
from gymnast.envs.imagined import ImaginedEnv
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.registration import IMAGINED_ID, register_envs, task_id
from gymnast.envs.starts import Start
from gymnast.envs.tasks import MT50
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig


def test_every_task_has_an_id_and_registering_again_changes_nothing():
    before = dict(gym.envs.registration.registry)
    register_envs()
    assert dict(gym.envs.registration.registry) == before
    assert all(task_id(task) in before for task in MT50) and IMAGINED_ID in before


def test_a_task_id_makes_the_real_world_env_with_its_settings_and_a_simulator_by_gap():
    env = gym.make("gymnast/drawer-open-v3", config=EnvConfig(image_size=32, horizon=3), gap="mild")
    assert isinstance(env.unwrapped, MetaWorldEnv) and env.unwrapped.task == "drawer-open-v3"
    assert env.unwrapped.gap.name == "mild"
    obs, info = env.reset(seed=0)
    assert obs["image"].shape == (32, 32, 3) and info["instruction"]
    truncated = False
    for _ in range(3):  # the env's own horizon ends the episode: no second time limit
        _, _, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        assert not terminated and "success" in info
    assert truncated
    env.close()


def test_the_imagined_id_makes_the_imagined_env_over_a_given_world_model():
    real = MetaWorldEnv("reach-v3", EnvConfig(image_size=32))
    obs, info = real.reset(seed=0)
    real.close()
    model = EmbeddedWorldModel(EmbeddedWorldModelConfig(image_size=32, latent_channels=8, widths=(8, 8), blocks=1,
                                                        action_width=8, bf16=False)).eval()
    start = Start("reach-v3", 0, info["instruction"], obs["image"][None].copy())
    env = gym.make(IMAGINED_ID, model=model, starts=[start], chunk_size=2, horizon=4)
    assert isinstance(env.unwrapped, ImaginedEnv)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs["image"], start.frames[-1])
    with torch.no_grad():
        obs, *_ = env.step(np.zeros((2, 4), dtype=np.float32))
    assert obs["image"].shape == (32, 32, 3)
    env.close()


def test_an_unknown_task_id_is_gymnasiums_clear_error():
    with pytest.raises(gym.error.NameNotFound):
        gym.make("gymnast/no-such-task-v3")
