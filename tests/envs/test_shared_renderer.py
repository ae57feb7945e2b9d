"""Environments of one scene share a GL context; what they render is what a private one renders."""

import numpy as np
import pytest

from gymnast.config import EnvConfig
from gymnast.envs import render
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.render import SceneRenderer


@pytest.mark.parametrize("task, gap", [("drawer-open-v3", "none"), ("pick-place-v3", "mild")])
def test_a_shared_context_renders_each_env_exactly_as_its_own_would(task, gap):
    config = EnvConfig(image_size=64)
    envs = [MetaWorldEnv(task, config=config, gap=gap) for _ in range(3)]
    try:
        assert len({id(env._renderer._renderer) for env in envs}) == 1  # one context for the three
        rng = np.random.default_rng(0)
        for seed, env in enumerate(envs):
            env.reset(seed=seed)
            for _ in range(seed * 10):  # different states: different layouts, different arm poses
                env.step(rng.uniform(-1, 1, 4).astype(np.float32))
        for env in envs:
            own = SceneRenderer(env._mw.model, 64, 64, env._renderer.camera)  # a private context
            try:
                np.testing.assert_array_equal(env._renderer.render(env._mw.data, env.markers()),
                                              own.render(env._mw.data, env.markers()))
            finally:
                own.close()
    finally:
        for env in envs:
            env.close()


def test_the_context_is_released_when_its_last_user_closes():
    config = EnvConfig(image_size=24)  # a size no other test uses: no other env shares this context
    first, second = MetaWorldEnv("reach-v3", config=config), MetaWorldEnv("reach-v3", config=config)
    key = ("reach-v3", first.gap), 24, 24
    assert render._SHARED[key][1] == 2
    first.close()
    first.close()  # closing twice counts once
    assert render._SHARED[key][1] == 1
    second.reset(seed=0)  # the survivor still renders
    second.close()
    assert key not in render._SHARED


def test_different_gaps_do_not_share():
    config = EnvConfig(image_size=32)
    real, sim = MetaWorldEnv("reach-v3", config=config), MetaWorldEnv("reach-v3", config=config, gap="strong")
    try:
        assert real._renderer._renderer is not sim._renderer._renderer
    finally:
        real.close()
        sim.close()
