"""Several cameras: the extra views are rendered only when asked, the primary view never changes,
the observed image shows the views side by side, and the gripper and hand views magnify what the
gripper reaches for."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import gymnast  # noqa: F401
from gymnast.config import EnvConfig
from gymnast.envs.cameras import GRIPPER_CAMERA, HAND_ZOOM, camera_pose
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.gap import get_gap
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.visibility import object_pixel_counts

BOTH = EnvConfig(image_size=32, horizon=30, cameras=("front", "gripper"))


def test_the_front_frames_are_the_same_whatever_other_cameras_are_rendered():
    one, two = MetaWorldEnv("pick-place-v3", EnvConfig(image_size=32, horizon=30)), MetaWorldEnv("pick-place-v3", BOTH)
    expert = ScriptedExpert("pick-place-v3")
    try:
        first, second = one.reset(seed=3)[0], two.reset(seed=3)[0]
        for _ in range(12):
            assert list(second["images"]) == ["front", "gripper"] and second["image"].shape == (32, 64, 3)
            np.testing.assert_array_equal(second["image"][:, :32], second["images"]["front"])
            np.testing.assert_array_equal(second["image"][:, 32:], second["images"]["gripper"])
            np.testing.assert_array_equal(first["image"], second["images"]["front"])
            assert first["image"] is first["images"]["front"]  # one camera: its frame, as always
            action = expert(one.env_state)
            first, second = one.step(action)[0], two.step(action)[0]
        assert list(first["images"]) == ["front"]  # nothing else is rendered unless asked for
    finally:
        one.close()
        two.close()


def test_an_env_with_two_cameras_passes_gymnasium_check_env():
    env = MetaWorldEnv("drawer-open-v3", BOTH)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    env.close()


def test_the_gripper_camera_follows_the_gripper_and_the_gap_moves_it_like_the_front_one():
    config, gripper = EnvConfig(), np.array([0.1, 0.6, 0.2])
    pose = camera_pose("gripper", config, get_gap("none"), gripper)
    np.testing.assert_allclose(pose.lookat, gripper + GRIPPER_CAMERA.lookat)
    strong = get_gap("strong")
    shifted = camera_pose("gripper", config, strong, gripper)
    front, front_shifted = camera_pose("front", config, get_gap("none"), gripper), camera_pose("front", config, strong, gripper)
    assert shifted.azimuth - pose.azimuth == front_shifted.azimuth - front.azimuth != 0


def test_the_hand_view_is_the_front_view_looking_closer_at_the_gripper_and_the_gap_moves_it_alike():
    config, gripper = EnvConfig(), np.array([0.1, 0.6, 0.2])
    front, hand = (camera_pose(name, config, get_gap("none"), gripper) for name in ("front", "hand"))
    np.testing.assert_allclose(hand.lookat, gripper)
    assert (hand.azimuth, hand.elevation) == (front.azimuth, front.elevation)
    assert hand.distance == pytest.approx(front.distance / HAND_ZOOM)
    strong = get_gap("strong")
    shifted, front_shifted = camera_pose("hand", config, strong, gripper), camera_pose("front", config, strong, gripper)
    assert shifted.azimuth - hand.azimuth == front_shifted.azimuth - front.azimuth != 0


@pytest.mark.parametrize("view", ["gripper", "hand"])
def test_the_gripper_and_hand_views_magnify_the_object_the_gripper_reaches_for(view):
    front = MetaWorldEnv("pick-place-v3", EnvConfig(image_size=48))
    gripper = MetaWorldEnv("pick-place-v3", EnvConfig(image_size=48, cameras=(view, "front")))
    expert = ScriptedExpert("pick-place-v3")
    try:
        for env in (front, gripper):
            env.reset(seed=0)
        for _ in range(25):  # the expert has lowered the gripper onto the puck
            action = expert(front.env_state)
            front.step(action)
            gripper.step(action)
        # Segmentation is of the primary (first) view: the front camera in one, the other view in the other.
        assert object_pixel_counts(gripper)["obj"] >= 5 * object_pixel_counts(front)["obj"]
    finally:
        front.close()
        gripper.close()


@pytest.mark.parametrize("cameras", [(), ("front", "front"), ("wrist",)])
def test_unknown_missing_or_repeated_cameras_are_refused_with_the_known_names(cameras):
    with pytest.raises(ValueError, match=r"one or more distinct names of \('front', 'gripper', 'hand'\)"):
        EnvConfig(cameras=cameras)
