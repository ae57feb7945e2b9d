"""Iter-SFT, World-Gymnast's strongest non-RL baseline: imitate your own judged successes.

The SFT policy is rolled out in the world model from every dataset scene, the judge keeps the
rollouts it calls successful, and the policy is fine-tuned on them mixed 1:1 with the
demonstrations. It uses the same world model, judge and start states as world-model RL, and no
real interactions, so the two differ only in how the judged rollouts are used: imitated, or
weighed against each other by GRPO.

Legend: R rollouts, S policy calls, K actions per call, A action dimensions, H/W image size.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.experiment.config import ExperimentConfig
from gymnast.policy.sft import DemoSet
from gymnast.rl.rollout import Rollouts, dataset_starts
from gymnast.utils.checkpoint import has_checkpoint

logger = logging.getLogger(__name__)


def rollout_samples(rollouts: Rollouts, chunk_size: int) -> DemoSet:
    """Every executed policy call of `rollouts` as an SFT sample: the image it saw and the K
    actions it then executed (a chunk cut short by the rollout's end is masked)."""
    calls = rollouts.observations.shape[1]
    steps = torch.arange(calls * chunk_size).view(calls, chunk_size)  # (S, K) action index of each slot
    valid = steps.unsqueeze(0) < rollouts.lengths.view(-1, 1, 1)  # (R, S, K)
    used = valid[:, :, 0]  # (R, S) calls that executed at least one action
    padded = torch.zeros(len(rollouts.actions), calls * chunk_size, rollouts.actions.shape[-1])
    padded[:, : rollouts.actions.shape[1]] = rollouts.actions[:, : calls * chunk_size]
    chunks = padded.view(len(rollouts.actions), calls, chunk_size, -1)  # (R, S, K, A)
    instructions = list(dict.fromkeys(rollouts.instructions))
    which = torch.tensor([instructions.index(text) for text in rollouts.instructions]).view(-1, 1).expand(-1, calls)
    states = None if rollouts.states is None else rollouts.states[used]
    return DemoSet(rollouts.observations[used], chunks[used], valid[used], which[used], instructions, [], states)


def imagine_successes(policy_run: Path, wm_run: Path, judge_run: Path, data: Path, config: ExperimentConfig,
                      progress: bool = True) -> tuple[DemoSet | None, dict]:
    """The SFT policy's judged-successful imagined rollouts from every dataset scene, as SFT
    samples (None if the judge passed none), and what was imagined (``rollouts``,
    ``judged_successes``, ``samples``)."""
    from gymnast.envs.imagined import BatchedImaginedEnv
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.policy.load import load_policy
    from gymnast.reward.select import make_reward
    from gymnast.reward.spec import RewardSpec
    from gymnast.rl.rollout import collect_rollouts, concat_rollouts, score_groups
    from gymnast.world_model.base import load_world_model
    from gymnast.world_model.views import model_cameras

    policy, world_model = load_policy(policy_run), load_world_model(wm_run)
    judge = make_reward(RewardSpec.judge(judge_run))
    size = config.iter_sft.group_size
    cameras = model_cameras(world_model)  # the views the world model imagines, as the policy sees them
    starts = [start for start in dataset_starts(data, resolve_tasks(config.tasks), cameras=cameras or None)
              for _ in range(size)]
    env = BatchedImaginedEnv(world_model, min(len(starts), config.rl.starts_per_step * size), policy.chunk_size,
                             config.rl.horizon)
    generator = torch.Generator().manual_seed(config.seed)
    kept, scores = [], []
    try:
        for first in tqdm(range(0, len(starts), env.num_envs), desc="iter-sft imagine", disable=not progress):
            batch = starts[first: first + env.num_envs]
            real = len(batch)
            batch += [batch[0]] * (env.num_envs - real)  # a fixed-size env; the padding is dropped
            rollouts = collect_rollouts(env, policy, batch, config.rl.temperature, generator, seed=config.seed + first)
            rollouts = rollouts.select(torch.arange(real))
            verdict = score_groups(judge, rollouts, 1)
            scores.append(verdict)
            kept.append(rollouts.select(torch.nonzero(verdict > 0.5).view(-1)))
    finally:
        env.close()
    judged = torch.cat(scores)
    counts = {"rollouts": len(judged), "judged_successes": int((judged > 0.5).sum()), "samples": 0}
    if counts["judged_successes"] == 0:
        logger.warning("Iter-SFT: the judge called none of the %d imagined rollouts successful; the policy is "
                       "fine-tuned on the demonstrations alone", len(judged))
        return None, counts
    samples = rollout_samples(concat_rollouts([part for part in kept if len(part.starts)]), policy.chunk_size)
    counts["samples"] = len(samples.images)
    logger.info("Iter-SFT: %d of %d imagined rollouts judged successful (%d samples)", counts["judged_successes"],
                len(judged), counts["samples"])
    return samples, counts


def train_iter_sft(policy_run: Path, wm_run: Path, judge_run: Path, data: Path, out: Path,
                   config: ExperimentConfig, progress: bool = True) -> dict:
    """Runs Iter-SFT into `out`; returns what it imagined and kept."""
    samples, counts = imagine_successes(policy_run, wm_run, judge_run, data, config, progress)
    fine_tune_on_successes(policy_run, data, samples, out, config, progress)
    return counts


def fine_tune_on_successes(policy_run: Path, data: Path, samples: DemoSet | None, out: Path, config: ExperimentConfig,
                           progress: bool = True) -> None:
    """Iter-SFT's fine-tuning into `out`: `policy_run` on `samples` (successes, imagined or real)
    drawn 1:1 with `data`'s demonstrations (on the demonstrations alone where None), for
    ``iter_sft.steps`` at ``iter_sft.lr``."""
    from gymnast.policy.sft import train_sft

    sft = dataclasses.replace(config.sft, steps=config.iter_sft.steps, lr=config.iter_sft.lr,
                              warmup_steps=min(config.sft.warmup_steps, config.iter_sft.steps // 10),
                              checkpoint_every=config.iter_sft.steps)
    train_sft(data, out, sft, resume=has_checkpoint(out), progress=progress, init=policy_run,
              extra=samples)
