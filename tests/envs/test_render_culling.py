"""Leaving out the geoms a camera cannot see changes no pixel of any view."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.render import drop_unseen_geoms


@pytest.mark.parametrize("task", ["reach-v3", "pick-place-v3", "door-open-v3", "peg-insert-side-v3"])
def test_every_view_is_the_same_image_with_the_unseen_geoms_left_out(task):
    env = MetaWorldEnv(task, EnvConfig(cameras=("front", "gripper", "hand")))
    actions = np.random.default_rng(0).uniform(-1, 1, size=(24, 4)).astype(np.float32)
    dropped = dict.fromkeys(env.config.cameras, 0)
    try:
        env.reset(seed=1)
        for step, action in enumerate(actions):
            env.step(action)
            if step % 3:
                continue
            for name, renderer in env._renderers.items():
                whole = renderer.render(env._mw.data, env.markers(), cull=False)
                culled = renderer.render(env._mw.data, env.markers(), cull=True)
                np.testing.assert_array_equal(culled, whole, err_msg=f"{task} {name} view, step {step}")
                dropped[name] += renderer._renderer.scene.ngeom < renderer_geoms(renderer, env)
    finally:
        env.close()
    assert dropped["gripper"] > 0  # the wrist camera sees little of the arm: there is something to leave out


def renderer_geoms(renderer, env) -> int:
    """How many geoms the scene holds without culling (markers included)."""
    renderer._update(env._mw.data, env.markers(), cull=False)
    return renderer._renderer.scene.ngeom


def test_a_stereo_or_orthographic_frustum_is_left_whole():
    env = MetaWorldEnv("reach-v3", EnvConfig(cameras=("gripper",)))
    try:
        env.reset(seed=0)
        renderer = env._renderers["gripper"]
        renderer._update(env._mw.data, env.markers())
        scene = renderer._renderer.scene
        whole = scene.ngeom
        scene.stereo = mujoco.mjtStereo.mjSTEREO_SIDEBYSIDE
        assert drop_unseen_geoms(scene, 1.0) == 0 and scene.ngeom == whole
        scene.stereo = mujoco.mjtStereo.mjSTEREO_NONE
        scene.camera[0].orthographic = 1
        assert drop_unseen_geoms(scene, 1.0) == 0 and scene.ngeom == whole
        scene.camera[0].orthographic = 0
        assert drop_unseen_geoms(scene, 1.0) > 0 and scene.ngeom < whole
    finally:
        env.close()
