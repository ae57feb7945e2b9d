"""Policies of several cameras: each view is encoded alone, SFT trains on a two-camera dataset,
and evaluation and RL render the views the policy was trained on."""

from __future__ import annotations

import json

import pytest
import torch

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.policy.load import load_policy, policy_env_config
from gymnast.policy.sft import random_shift
from gymnast.policy.vla import EmbeddedVLA, VLAConfig

TWO = ("front", "gripper")


def test_each_camera_is_encoded_alone_so_one_view_never_leaks_into_the_others_tokens():
    policy = EmbeddedVLA(VLAConfig(width=32, layers=1, heads=2, image_size=32, cameras=TWO), pretrained_vision=False)
    images = torch.randint(0, 256, (2, 32, 64, 3), dtype=torch.uint8)
    other = images.clone()
    other[:, :, 32:] = torch.randint(0, 256, (2, 32, 32, 3), dtype=torch.uint8)  # a new gripper view
    text = policy.embed_instructions(["reach", "reach"], 2)
    first, second = policy.memory(images, text), policy.memory(other, text)
    assert first.shape == (2, 1 + 2 * 4, 32)  # the instruction and 2 x 2 tokens for each view
    torch.testing.assert_close(first[:, :5], second[:, :5])  # the instruction and the front view's
    assert not torch.allclose(first[:, 5:], second[:, 5:])
    with pytest.raises(ValueError, match=r"images must be \(B, 32, 64, 3\)"):
        policy.memory(images[:, :, :32], text)  # one camera's frame for a two-camera policy


def test_augmentation_shifts_each_camera_alone():
    images = torch.zeros(3, 16, 32, 3, dtype=torch.uint8)
    images[:, :, 16:] = 255  # a black front view beside a white gripper view
    shifted = random_shift(images, 4, torch.Generator().manual_seed(0), views=2)
    assert (shifted[:, :, :16] == 0).all() and (shifted[:, :, 16:] == 255).all()  # nothing crosses the seam
    whole = random_shift(images, 4, torch.Generator().manual_seed(0))
    assert not ((whole[:, :, :16] == 0).all() and (whole[:, :, 16:] == 255).all())


@pytest.mark.parametrize("family", ["tokens", "flow"])
def test_sft_on_two_cameras_makes_a_policy_that_eval_shows_both_views(family, two_camera_demos, tmp_path):
    run, report = tmp_path / "run", tmp_path / "eval.json"
    main(["sft", "--data", str(two_camera_demos), "--out", str(run), "--preset", "debug", "--cameras", "front,gripper",
          "--policy-type", family])
    policy = load_policy(run)
    assert policy.config.cameras == TWO and policy.observed_shape == (32, 64, 3)
    main(["sft", "--out", str(run), "--resume"])  # the cameras come from the run
    main(["eval", "--policy", str(run), "--tasks", "reach-v3", "--episodes", "1", "--workers", "1",
          "--env.image-size", "32", "--env.horizon", "10", "--out", str(report)])
    evaluated = json.loads(report.read_text())
    assert evaluated["episodes"] == 1 and evaluated["config"]["env"]["cameras"] == list(TWO)


def test_a_policy_acts_on_its_own_cameras_and_a_conflicting_camera_is_refused(two_camera_demos, tmp_path):
    one, two = tmp_path / "one", tmp_path / "two"
    main(["sft", "--data", str(two_camera_demos), "--out", str(one), "--preset", "debug", "--camera", "gripper"])
    assert load_policy(one).config.cameras == ("gripper",)
    assert policy_env_config(EnvConfig(), str(one)).cameras == ("gripper",)
    # A one-camera policy of another robot's camera acts on the front view, as before cameras were a setting.
    assert VLAConfig(cameras=("observation.images.top",)).env_cameras == ("front",)
    main(["sft", "--data", str(two_camera_demos), "--out", str(two), "--preset", "debug", "--cameras", "front,gripper"])
    assert policy_env_config(EnvConfig(), str(two)).cameras == TWO
    with pytest.raises(ValueError, match="renders cameras gripper, but the policy .* acts on front,gripper"):
        policy_env_config(EnvConfig(cameras=("gripper",)), str(two))


def test_a_policy_is_shown_the_image_size_it_was_trained_on(two_camera_demos, tmp_path):
    run = tmp_path / "run"  # the debug dataset's frames are 32 px, so the policy sees 32 px
    main(["sft", "--data", str(two_camera_demos), "--out", str(run), "--preset", "debug", "--camera", "front"])
    assert policy_env_config(EnvConfig(), str(run)).image_size == 32
    assert policy_env_config(EnvConfig(), load_policy(run)).image_size == 32
    assert policy_env_config(EnvConfig(image_size=32), str(run)).image_size == 32
    with pytest.raises(ValueError, match="renders 48px images, but the policy .* was trained on 32px"):
        policy_env_config(EnvConfig(image_size=48), str(run))
    assert policy_env_config(EnvConfig(image_size=48), "expert").image_size == 48


def test_a_one_camera_policys_rollouts_are_recorded_with_more_cameras_than_it_sees(two_camera_demos, tmp_path):
    from gymnast.data.lerobot import EpisodeDataset

    run, rollouts = tmp_path / "front", tmp_path / "rollouts"
    main(["sft", "--data", str(two_camera_demos), "--out", str(run), "--preset", "debug", "--camera", "front"])
    main(["collect", "--policy", str(run), "--tasks", "reach-v3", "--episodes-per-task", "1", "--noise", "0",
          "--cameras", "front,gripper", "--env.image-size", "32", "--env.horizon", "10", "--workers", "1",
          "--out", str(rollouts)])
    episode = EpisodeDataset(rollouts, cameras=TWO).load(0)
    assert list(episode.views) == list(TWO) and episode.length == 10  # the policy acted on the front view alone
