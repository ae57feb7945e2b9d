"""Environments: the Meta-World "real world", its software-simulator variants, the imagined
environment over a learned world model, and the start states and vector envs rollouts run in.

Importing this package registers them with Gymnasium (`gymnast.envs.registration`):
``gymnasium.make("gymnast/drawer-open-v3")``, ``gymnasium.make("gymnast/imagined", model=...)``.
"""

from gymnast.envs.registration import register_envs

register_envs()
