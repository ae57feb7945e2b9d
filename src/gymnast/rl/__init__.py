"""Reinforcement learning of the policy (GRPO) in the real, simulated or imagined world."""
