"""Environments: the Meta-World "real world", its software-simulator variants, the imagined
environment over a learned world model, and the start states and vector envs rollouts run in."""
