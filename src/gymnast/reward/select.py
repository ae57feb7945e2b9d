"""Rewards from their specs (`gymnast.reward.spec.RewardSpec`, parsed from the command line's
`--reward judge:RUN | state:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense`).

The verified reward imagines with the world model the rollouts were imagined with, so it needs
that model; the others need nothing more than their spec says. `measure_judge` measures a judge
given by its spec (``gymnast eval-judge``); it lives here, above the learned judge's training,
because it builds the judge from its spec.
"""

from __future__ import annotations

from pathlib import Path

import torch

from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.reward.base import Reward
from gymnast.reward.spec import RewardSpec
from gymnast.utils.atomic import write_json
from gymnast.utils.device import resolve_device
from gymnast.world_model.base import WorldModel


def make_reward(spec: RewardSpec, world_model: WorldModel | None = None) -> Reward:
    """The reward `spec` names.

    Raises:
        ValueError: `verified` without a world model.
        FileNotFoundError: `judge:RUN` where RUN has no checkpoint.
    """
    if spec.kind == "all":
        from gymnast.reward.consensus import ConsensusReward

        return ConsensusReward([make_reward(member, world_model) for member in spec.members],
                               [str(member) for member in spec.members])
    if spec.kind == "judge":
        from gymnast.reward.judges.train import load_judge

        return load_judge(spec.run)
    if spec.kind == "state":
        from gymnast.reward.state_reward import StateReward
        from gymnast.world_model.state_model import load_state_models

        return StateReward(load_state_models(spec.run))
    if spec.kind == "vlm":
        from gymnast.reward.chat.vlm import VLMJudge, VLMJudgeConfig

        return VLMJudge(VLMJudgeConfig(model=spec.model, base_url=spec.base_url))
    if spec.kind == "verified":
        if world_model is None:
            raise ValueError("--reward verified imagines the reference actions: it needs a world model (--wm)")
        from gymnast.reward.verified import VerifiedReward

        return VerifiedReward(world_model)
    from gymnast.reward.sim import SimDense, SimSuccess

    return SimSuccess() if spec.kind == "sim" else SimDense()


def measure_judge(reward: RewardSpec, data: Path, out: Path, wm: Path | None = None, heldout_fraction: float = 0.1,
                  device: str = "auto", camera: str | None = None, keys: FeatureKeys = FeatureKeys()) -> dict:
    """`evaluate_judge` of the 0/1 judge `reward` (judge:RUN or vlm:MODEL@BASE_URL) on the episodes of
    the held-out scenes of `data` (its `camera`, or the cameras a judge of several was trained on;
    its actions and states read by `keys`), and with `wm`
    on its re-imaginings of them, or `evaluate_progress` of a progress judge (which gives degrees,
    not verdicts); written to `out` (JSON). A learned judge and the world model run on `device`."""
    from gymnast.reward.judges.progress import evaluate_progress
    from gymnast.reward.judges.measure import evaluate_judge
    from gymnast.reward.judges.train import saved_judge_config
    from gymnast.reward.judges.videos import heldout_videos

    if reward.kind not in ("judge", "vlm"):
        raise ValueError(f"eval-judge measures judges (judge:RUN or vlm:MODEL@BASE_URL), got {str(reward)!r}")
    where = resolve_device(device)
    judge = make_reward(reward)
    if isinstance(judge, torch.nn.Module):  # a learned judge; a VLM runs wherever its server does
        judge.to(where)
    measure = evaluate_judge if judge.binary else evaluate_progress
    cameras = judge.config.cameras if reward.kind == "judge" and len(judge.config.cameras) > 1 else None
    dataset = EpisodeDataset(data, camera if cameras is None else cameras[0], cameras, keys=keys)
    if reward.kind == "judge" and dataset.image_shape[0] != judge.config.image_size:
        # Frames of another size are fitted as the judge's training fitted them (its saved `fit`).
        dataset = dataset.fitted(judge.config.image_size, saved_judge_config(reward.run).fit)
    report = measure(judge, heldout_videos(dataset, heldout_fraction, wm, where))
    report |= {"reward": str(reward), "data": str(data), "wm": str(wm) if wm else None,
               "camera": ",".join(dataset.cameras)}
    write_json(out, report)
    return report
