"""Rewards by name, as the command line gives them: `--reward judge:RUN | vlm:MODEL@BASE_URL |
verified | sim | sim-dense`.

The verified reward imagines with the world model the rollouts were imagined with, so it needs
that model; the others need nothing more than their name says.
"""

from __future__ import annotations

from pathlib import Path

from gymnast.reward.base import Reward
from gymnast.world_model.base import WorldModel

REWARD_FORMS = "judge:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense"


def make_reward(spec: str, world_model: WorldModel | None = None) -> Reward:
    """The reward named by `spec` (see `REWARD_FORMS`).

    Raises:
        ValueError: an unknown or malformed name, or `verified` without a world model.
        FileNotFoundError: `judge:RUN` where RUN has no checkpoint.
    """
    kind, _, argument = spec.partition(":")
    if kind == "judge" and argument:
        from gymnast.reward.train_judge import load_judge

        return load_judge(Path(argument))
    if kind == "vlm" and "@" in argument:
        from gymnast.reward.vlm import VLMJudge, VLMJudgeConfig

        model, _, base_url = argument.partition("@")
        if model and base_url:
            return VLMJudge(VLMJudgeConfig(model=model, base_url=base_url))
    if spec == "verified":
        if world_model is None:
            raise ValueError("--reward verified imagines the reference actions: it needs a world model (--wm)")
        from gymnast.reward.verified import VerifiedReward

        return VerifiedReward(world_model)
    if spec in ("sim", "sim-dense"):
        from gymnast.reward.sim import SimDense, SimSuccess

        return SimSuccess() if spec == "sim" else SimDense()
    raise ValueError(f"unknown reward {spec!r}; the forms are {REWARD_FORMS}")
