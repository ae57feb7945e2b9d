"""Near misses: the task's own expert acting as if the objects and the goal were a few centimetres
off, recorded beside the experts on the same scenes so that a world model sees the hand arrive and
nothing happen."""

from __future__ import annotations

import numpy as np

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, EpisodeJob, plan_episodes, record_episode
from gymnast.envs.experts import NEAR_MISS_CM, NearMissExpert, ScriptedExpert, make_behaviour


def test_near_misses_are_planned_on_the_experts_seeds_after_the_failures():
    jobs = plan_episodes(CollectConfig(tasks="reach-v3", episodes_per_task=2, noise=(0.0,), failure_fraction=0.5,
                                       near_misses=2))
    assert [(j.behaviour, j.seed) for j in jobs] == [("expert", 0), ("expert", 1), ("random", 0),
                                                     ("near_miss_expert", 0), ("near_miss_expert", 1)]
    assert len({job.key for job in jobs}) == len(jobs)


def test_the_near_miss_expert_acts_on_the_scene_moved_by_a_few_centimetres_but_not_on_the_hand():
    state = np.random.default_rng(0).uniform(-0.5, 0.5, 39)
    offset = np.array([0.03, -0.04, 0.0])
    moved = state.copy()
    for start in (4, 11, 22, 29, 36):  # both objects, now and one step before, and the goal
        moved[start:start + 3] += offset
    np.testing.assert_allclose(NearMissExpert("reach-v3", offset)(state), ScriptedExpert("reach-v3")(moved))
    drawn = make_behaviour("near_miss_expert", "push-v3", 0.0, seed=3)._offset
    assert abs(np.linalg.norm(drawn) * 100 - NEAR_MISS_CM) < 1e-9 and drawn[2] == 0.0  # horizontal


def test_a_reach_near_miss_stops_its_distance_from_the_goal_and_fails():
    episode = record_episode(EpisodeJob("reach-v3", "near_miss_expert", 0.0, 0, "none", EnvConfig(image_size=32, horizon=150)))
    hand, goal = episode.env_states[-1, 0:3], episode.env_states[-1, 36:39]
    assert not episode.info.success and episode.info.behaviour == "near_miss_expert"
    assert 0.6 * NEAR_MISS_CM < np.linalg.norm(hand - goal) * 100 < 1.5 * NEAR_MISS_CM
