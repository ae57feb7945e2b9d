"""The real world: determinism, the Gymnasium contract, goals in view, perturbations, sim gaps."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import gymnast  # noqa: F401
from gymnast.config import EnvConfig
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.gap import GAPS
from gymnast.envs.instructions import all_instructions
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.tasks import EVAL_SEEDS, MT10, eval_seed, resolve_tasks
from gymnast.envs.visibility import GOAL_MARKER, effective_width, object_pixel_counts

SMALL = EnvConfig(image_size=48, horizon=40)


def rollout(env: MetaWorldEnv, seed: int, actions: np.ndarray) -> np.ndarray:
    obs, _ = env.reset(seed=seed)
    frames = [obs["image"]]
    for action in actions:
        obs, *_ = env.step(action)
        frames.append(obs["image"])
    return np.stack(frames)


@pytest.fixture(scope="module")
def push_env():
    env = MetaWorldEnv("push-v3", SMALL)
    yield env
    env.close()


def test_same_task_and_seed_give_identical_frames_for_identical_actions(push_env):
    actions = np.random.default_rng(0).uniform(-1, 1, size=(15, 4)).astype(np.float32)
    other = MetaWorldEnv("push-v3", SMALL)  # a second instance must agree too, not just a replay
    np.testing.assert_array_equal(rollout(push_env, 7, actions), rollout(other, 7, actions))
    np.testing.assert_array_equal(rollout(push_env, 7, actions), rollout(push_env, 7, actions))
    other.close()


def test_different_seeds_start_from_different_states(push_env):
    first = push_env.reset(seed=1)[1]["env_state"]
    second = push_env.reset(seed=2)[1]["env_state"]
    assert not np.allclose(first, second)


def test_env_passes_gymnasium_check_env():
    env = MetaWorldEnv("drawer-open-v3", SMALL)
    check_env(env, skip_render_check=True)
    env.close()


def test_observation_matches_its_space_and_hides_the_simulator_state(push_env):
    obs, info = push_env.reset(seed=0)
    assert push_env.observation_space.contains(obs)
    assert set(obs) == {"image", "images", "state"}
    assert list(obs["images"]) == ["front"] and obs["images"]["front"] is obs["image"]
    assert obs["image"].shape == (48, 48, 3) and obs["image"].dtype == np.uint8
    assert info["env_state"].shape == (39,)


def test_expert_success_terminates_the_episode():
    env = MetaWorldEnv("reach-v3", EnvConfig(image_size=32, horizon=150))
    env.reset(seed=3)
    expert = ScriptedExpert("reach-v3")
    for step in range(150):
        _, _, terminated, truncated, info = env.step(expert(env.env_state))
        if terminated or truncated:
            break
    assert terminated and not truncated and info["success"]
    assert step < 149
    env.close()


def test_horizon_truncates_without_success(push_env):
    push_env.reset(seed=0)
    for step in range(SMALL.horizon):
        _, _, terminated, truncated, info = push_env.step(np.zeros(4, dtype=np.float32))
        assert not terminated
        assert truncated == (step == SMALL.horizon - 1)
    assert not info["success"]


def test_wrong_action_shape_is_rejected_with_both_shapes(push_env):
    push_env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(4,\).*\(3,\)"):
        push_env.step(np.zeros(3))


def test_unknown_task_lists_the_valid_names():
    with pytest.raises(ValueError, match="drawer-open-v3") as error:
        resolve_tasks("drawer-opne-v3")
    assert "mt10" in str(error.value) and "window-close-v3" in str(error.value)


def test_task_sets_expand_in_order():
    assert resolve_tasks("mt10") == MT10
    assert len(resolve_tasks("mt50")) == 50
    assert resolve_tasks("reach-v3,mt10")[0] == "reach-v3" and len(resolve_tasks("reach-v3,mt10")) == 10


def test_instruction_is_reported_and_comes_from_the_requested_split():
    train = MetaWorldEnv("drawer-close-v3", SMALL)
    heldout = MetaWorldEnv("drawer-close-v3", SMALL, instruction_split="heldout")
    _, info = train.reset(seed=5)
    assert info["instruction"] == train.instruction in all_instructions("drawer-close-v3", "train")
    heldout.reset(seed=5)
    assert heldout.instruction in all_instructions("drawer-close-v3", "heldout")
    _, info = train.reset(seed=5, options={"instruction": "close it"})
    assert info["instruction"] == "close it"


def test_evaluation_seeds_are_disjoint_from_data_seeds():
    assert eval_seed(0) == EVAL_SEEDS.start and eval_seed(0) >= 1_000_000
    with pytest.raises(ValueError):
        eval_seed(-1)


@pytest.mark.parametrize("task", MT10)
def test_every_mt10_object_and_goal_spans_several_pixels_at_the_default_size(task):
    env = MetaWorldEnv(task)
    env.reset(seed=0)
    counts = object_pixel_counts(env)
    env.close()
    assert counts, f"no task object visible in {task}"
    for name, pixels in counts.items():
        assert effective_width(pixels) >= 3.0, f"{task}: {name} covers only {pixels} pixels"


def test_goal_marker_is_drawn_where_the_goal_is_a_point_in_space():
    reach = MetaWorldEnv("reach-v3", SMALL)
    reach.reset(seed=0)
    assert object_pixel_counts(reach)[GOAL_MARKER] > 0
    drawer = MetaWorldEnv("drawer-open-v3", SMALL)
    drawer.reset(seed=0)
    assert GOAL_MARKER not in object_pixel_counts(drawer)


@pytest.mark.parametrize("level, centimetres", [("minor", 2.5), ("major", 5.0)])
def test_perturbations_move_object_goal_and_hand_by_their_distance(level, centimetres):
    base = MetaWorldEnv("pick-place-v3", SMALL)
    measured = {}
    for target in ("object", "goal", "robot"):
        env = MetaWorldEnv("pick-place-v3", SMALL, perturbation=f"{level}:{target}")
        for seed in range(3):
            base.reset(seed=seed)
            env.reset(seed=seed)
            moved = {
                "object": np.linalg.norm(env.env_state[4:6] - base.env_state[4:6]),
                "goal": np.linalg.norm(env.goal_position[:2] - base.goal_position[:2]),
                "robot": np.linalg.norm(env.hand_position - base.hand_position),
            }
            measured.setdefault(target, []).append(100 * moved[target])
            for other in set(moved) - {target}:
                assert moved[other] < 1e-3, f"{target} perturbation also moved {other}"
        env.close()
    for target, values in measured.items():
        np.testing.assert_allclose(values, centimetres, atol=0.1, err_msg=target)


def test_goal_perturbation_is_refused_where_the_goal_follows_the_object():
    with pytest.raises(ValueError, match="goal"):
        MetaWorldEnv("drawer-open-v3", SMALL, perturbation="minor:goal")


def test_gap_levels_change_the_pictures_and_the_physics():
    actions = np.random.default_rng(1).uniform(-1, 1, size=(30, 4)).astype(np.float32)
    real = MetaWorldEnv("push-v3", SMALL)
    frames, hands = {}, {}
    for level in ("none", "mild", "strong"):
        env = real if level == "none" else MetaWorldEnv("push-v3", SMALL, gap=level)
        frames[level] = rollout(env, 4, actions).astype(np.float32)
        hands[level] = env.hand_position
        assert env.gap == GAPS[level]
    for level in ("mild", "strong"):
        assert np.abs(frames[level][0] - frames["none"][0]).mean() > 5.0, f"{level} looks like the real world"
    drift = {level: np.linalg.norm(hands[level] - hands["none"]) for level in ("mild", "strong")}
    assert drift["mild"] > 0.005, "mild gap did not change the dynamics"
    assert drift["strong"] > drift["mild"], f"strong should drift more than mild: {drift}"


def test_unknown_gap_level_is_refused():
    with pytest.raises(ValueError, match="mild"):
        MetaWorldEnv("push-v3", SMALL, gap="huge")
