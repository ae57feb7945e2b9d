"""Rewards for rollouts: the `Reward` contract and its implementations."""
