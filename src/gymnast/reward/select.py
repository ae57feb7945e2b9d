"""Rewards by name, as the command line gives them: `--reward judge:RUN | vlm:MODEL@BASE_URL |
verified | sim | sim-dense`.

The verified reward imagines with the world model the rollouts were imagined with, so it needs
that model; the others need nothing more than their name says. `measure_judge` measures a judge
given by its name (``gymnast eval-judge``); it lives here, above the learned judge's training,
because it builds the judge by name.
"""

from __future__ import annotations

from pathlib import Path

from gymnast.data.lerobot import EpisodeDataset
from gymnast.reward.base import Reward
from gymnast.utils.atomic import write_json
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


def measure_judge(reward: str, data: Path, out: Path, wm: Path | None = None, heldout_fraction: float = 0.1) -> dict:
    """`evaluate_judge` of the 0/1 judge `reward` (judge:RUN or vlm:MODEL@BASE_URL) on the episodes of
    the held-out scenes of `data`, and with `wm` on its re-imaginings of them; written to `out` (JSON)."""
    from gymnast.reward.train_judge import evaluate_judge, heldout_videos

    if not reward.startswith(("judge:", "vlm:")):
        raise ValueError(f"eval-judge measures judges (judge:RUN or vlm:MODEL@BASE_URL), got {reward!r}")
    report = evaluate_judge(make_reward(reward), heldout_videos(EpisodeDataset(data), heldout_fraction, wm))
    report |= {"reward": reward, "data": str(data), "wm": str(wm) if wm else None}
    write_json(out, report)
    return report
