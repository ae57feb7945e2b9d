"""The reward-hacking watch, against the real simulator."""

import torch
from rl_helpers import POLICY

from gymnast.config import EnvConfig
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import REAL
from gymnast.policy.load import load_policy
from gymnast.rl.evaluate import watch_hacking
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
