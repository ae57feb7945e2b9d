"""One RL step's batch: start states, rollouts, rewards, and dynamic sampling.

Legend: B start states (groups) per round, G rollouts per start, R = B * G rollouts.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import torch

from gymnast.config import EnvConfig
from gymnast.envs.tasks import DATA_SEEDS
from gymnast.reward.base import Reward, RewardContext
from gymnast.rl import grpo
from gymnast.rl.evaluate import scene_starts, verdicts
from gymnast.rl.rollout import Rollouts, Start, collect_rollouts

if TYPE_CHECKING:
    from gymnast.rl.train import RLConfig


def start_sampler(tasks: Sequence[str], dataset: list[Start] | None, config: EnvConfig
                  ) -> Callable[[int, torch.Generator], list[Start]]:
    """`draw(count, generator)`: start states drawn from the dataset's scenes, or (`dataset` None)
    fresh scenes of `tasks` from random data seeds, rendered by a reset."""

    def draw(count: int, generator: torch.Generator) -> list[Start]:
        if dataset is not None:
            return [dataset[i] for i in torch.randint(len(dataset), (count,), generator=generator).tolist()]
        picks = torch.randint(len(tasks), (count,), generator=generator).tolist()
        seeds = torch.randint(DATA_SEEDS.start, DATA_SEEDS.stop, (count,), generator=generator).tolist()
        return scene_starts([(tasks[t], seed) for t, seed in zip(picks, seeds)], config)

    return draw


def gather_batch(env, policy, reward: Reward, draw_starts: Callable[[int, torch.Generator], list[Start]],
                 config: RLConfig, sampler: torch.Generator, actions: torch.Generator
                 ) -> tuple[Rollouts | None, torch.Tensor | None, dict[str, float]]:
    """Rollouts of B groups with something to learn from, refilled from fresh starts for at most
    `max_rounds` rounds; returns (kept rollouts or None, their (R,) scores, metrics).

    Dynamic sampling: with a binary reward a group is kept when its success rate lies in
    [keep_low, keep_high]; with a continuous one (dense, verified) when its rewards differ at all,
    since a group of failures still ranks its rollouts by how close they came.
    """
    groups, size = config.starts_per_step, config.group_size
    kept: list[Rollouts] = []
    kept_scores: list[torch.Tensor] = []
    values: dict[str, float] = {"rollout/interactions": 0, "time/rollout_s": 0.0, "time/policy_s": 0.0,
                                "time/reward_s": 0.0}
    binary = getattr(reward, "binary", False)
    for round_ in range(config.max_rounds):
        starts = draw_starts(groups, sampler)
        seed = int(torch.randint(2**31 - 1, (1,), generator=sampler))
        timer: dict[str, float] = {}
        began = time.perf_counter()
        rollouts = collect_rollouts(env, policy, [start for start in starts for _ in range(size)], config.temperature,
                                    actions, seed, calls=-(-config.horizon // policy.chunk_size), timer=timer)
        values["time/rollout_s"] += time.perf_counter() - began
        values["time/policy_s"] += timer.get("policy_s", 0.0)
        began = time.perf_counter()
        scores = score_groups(reward, rollouts, size)  # (R,)
        values["time/reward_s"] += time.perf_counter() - began
        values["rollout/interactions"] += int(rollouts.lengths.sum())
        if round_ == 0:  # the first round is an unbiased sample of the current policy
            finite = scores[torch.isfinite(scores)]
            values |= {"reward/mean": finite.mean().item() if len(finite) else float("nan"),
                       "reward/std": finite.std().item() if len(finite) > 1 else float("nan"),
                       "rollout/success": torch.nanmean(verdicts(rollouts, scores, reward)).item(),
                       "rollout/length": rollouts.lengths.float().mean().item()}
        grouped = scores.view(groups, size)
        if binary:
            keep = grpo.keep_groups(grouped, config.keep_low, config.keep_high)
        else:
            keep = torch.tensor([len(set(row[torch.isfinite(row)].tolist())) > 1 for row in grouped])
        for g in keep.nonzero().flatten().tolist()[: groups - len(kept)]:
            index = torch.arange(g * size, (g + 1) * size)
            kept.append(rollouts.select(index))
            kept_scores.append(scores[index])
        if len(kept) == groups:
            break
    values |= {"rollout/kept_groups": len(kept), "rollout/rounds": round_ + 1}
    if not kept:
        return None, None, values
    return concat_rollouts(kept), torch.cat(kept_scores), values


def score_groups(reward: Reward, rollouts: Rollouts, size: int) -> torch.Tensor:
    """(R,) scores, reward called once per block of `size` rollouts that share a start state."""
    scores = []
    for first in range(0, len(rollouts.starts), size):
        block = rollouts.select(torch.arange(first, min(first + size, len(rollouts.starts))))
        scores.append(reward.score(block.frames, block.instructions, reward_context(block)).float().reshape(-1))
    return torch.cat(scores)


def reward_context(rollouts: Rollouts) -> RewardContext:
    """What the rewards may read besides the video (see `RewardContext`)."""
    references = [start.reference_actions for start in rollouts.starts]
    shortest = min(len(r) for r in references)  # a block shares one start, so all have one length
    return RewardContext(
        start=torch.from_numpy(np.stack([start.frames for start in rollouts.starts])),
        reference_actions=torch.from_numpy(np.stack([r[:shortest] for r in references])),
        success=rollouts.success,
        env_rewards=rollouts.env_rewards,
    )


def concat_rollouts(parts: list[Rollouts]) -> Rollouts:
    """One `Rollouts` of the parts in order (rollouts of one env share their shapes)."""
    tensors = {}
    for field in dataclasses.fields(Rollouts):
        values = [getattr(part, field.name) for part in parts]
        if field.name != "starts":
            tensors[field.name] = None if values[0] is None else torch.cat(values)
    return Rollouts(starts=tuple(start for part in parts for start in part.starts), **tensors)
