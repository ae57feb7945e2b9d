"""The reward-hacking watch, against the real simulator."""

import copy

import pytest
import torch
from rl_helpers import POLICY

from gymnast.config import EnvConfig
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import REAL, SIM
from gymnast.policy.load import load_policy
from gymnast.envs.starts import evaluation_starts
from gymnast.reward.sim import SimSuccess
from gymnast.rl.evaluate import (evaluate_in_env, evaluation_batch, policy_fingerprint, shared_evaluations, taking_turns,
                                  watch_hacking)
from gymnast.rl.rollout import collect_rollouts, dataset_starts

CONFIG = EnvConfig(image_size=96, horizon=60)


def test_replaying_real_rollouts_in_the_real_world_agrees_with_their_outcomes(rl_dataset):
    policy = load_policy(POLICY)
    starts = [start for start in dataset_starts(rl_dataset) for _ in range(2)]
    envs = EnvFactory(REAL, policy.chunk_size, CONFIG, "mild", workers=1)
    try:
        rollouts = collect_rollouts(envs.train(len(starts)), policy, starts, 1.0, torch.Generator().manual_seed(0))
        outcome = rollouts.success.float()
        watched = watch_hacking(envs, rollouts, outcome, outcome, count=len(starts))
        assert watched["eval/watch_agreement"] == 1.0
        assert watched["eval/watch_real_success"] == outcome.mean().item()
        assert watched["eval/watch_interactions"] == rollouts.lengths.sum().item()
        # The same replays judged by a verdict that calls everything a success: the failures are caught.
        watched = watch_hacking(envs, rollouts, outcome, torch.ones(len(starts)), count=len(starts))
        assert watched["eval/watch_false_success"] == 1 - outcome.mean().item()
    finally:
        envs.close()


def test_a_shared_evaluation_runs_once_and_gives_exactly_the_figures_of_running_it_again():
    policy = load_policy(POLICY)
    starts = evaluation_starts(["reach-v3", "drawer-close-v3"], 2, CONFIG)

    def evaluate(built: list) -> dict:
        envs = EnvFactory(REAL, policy.chunk_size, CONFIG, "none", workers=1, batch=4)
        try:
            figures = evaluate_in_env(envs, REAL, policy, SimSuccess(), starts, prefix="eval/real")
            built.append(bool(envs._envs))  # whether it built a simulator to run episodes in
            return figures
        finally:
            envs.close()

    built = []
    fresh = evaluate(built)
    with shared_evaluations():
        first, again = evaluate(built), evaluate(built)
        changed = copy.deepcopy(policy)
        with torch.no_grad():
            next(changed.parameters()).add_(0.5)
        assert policy_fingerprint(changed) != policy_fingerprint(policy)
    assert fresh == first == again and fresh["eval/real_episodes"] == 4 and "eval/real_success/reach-v3" in fresh
    assert built == [True, True, False]  # the repeated one ran no episode
    with shared_evaluations():
        assert evaluate(built) == fresh and built[-1]  # a new block runs it again


def test_every_env_but_the_training_one_is_closed_between_uses():
    envs = EnvFactory(SIM, 5, CONFIG, "mild", workers=1, batch=2)
    try:
        before = envs.get(SIM, envs.batch)  # the first evaluation's env, at its own batch
        real = envs.get(REAL, envs.batch)  # and the real world's evaluation beside it
        trained = envs.train(3)
        # Their simulator processes would otherwise sit idle, holding their scenes, for the whole run.
        assert before.closed and real.closed and not trained.closed
        assert envs.get(SIM, envs.batch) is trained and trained.num_envs == 3
        watched = envs.get(REAL, 4)  # the watch's replays
        envs.close_others()
        assert watched.closed and not trained.closed
        assert envs.train(3) is trained
    finally:
        envs.close()


def test_an_evaluation_simulates_its_own_episodes_and_no_padding():
    policy = load_policy(POLICY)
    starts = evaluation_starts(["reach-v3", "drawer-close-v3"], 1, CONFIG)
    envs = EnvFactory(REAL, policy.chunk_size, CONFIG, "none", workers=1, batch=8)  # a training batch of 8
    try:
        figures = evaluate_in_env(envs, REAL, policy, SimSuccess(), starts, prefix="eval/real")
        # Two episodes in an env of two: none of the six padding rollouts a batch of 8 would step.
        assert [env.num_envs for env in envs._envs.values()] == [2]
        assert figures["eval/real_episodes"] == 2
    finally:
        envs.close()


@pytest.mark.parametrize(("episodes", "batch", "size"), [(2, 8, 2), (64, 64, 64), (50, 64, 50), (100, 64, 50),
                                                         (129, 64, 43), (1, 1, 1)])
def test_evaluation_batches_are_the_fewest_of_equal_size(episodes, batch, size):
    assert evaluation_batch(episodes, batch) == size
    assert size * -(-episodes // size) - episodes < -(-episodes // batch)  # padding: under one rollout a batch


def test_an_evaluation_without_episodes_is_refused():
    with pytest.raises(ValueError, match="at least one"):
        evaluation_batch(0, 8)


def test_evaluation_batches_take_turns_over_the_tasks_as_training_batches_do():
    starts = evaluation_starts(["reach-v3", "drawer-close-v3"], 3, CONFIG)
    ordered = taking_turns(starts[:3] + starts[3:4])  # three reach, one drawer-close
    assert [start.task for start in ordered] == ["reach-v3", "drawer-close-v3", "reach-v3", "reach-v3"]
    assert sorted(start.seed for start in taking_turns(starts)) == sorted(start.seed for start in starts)
