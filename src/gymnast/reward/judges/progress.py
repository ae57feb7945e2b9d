"""The progress judge: how far along is the task in this frame? Meta-World's dense reward, read
from pixels.

Legend: B videos, T frames, N frames.

On the tasks the policy fails most, the 0/1 judges rank a group of the policy's rollouts no better
than chance, even on real video, while the simulator's dense reward ranks them well (`gymnast
rl-signal`, results/fidelity/signal/): a verdict says nothing about which of two failures came
closer, which is most of what GRPO has to learn from there. This judge learns the dense reward
itself, from every frame of real (and re-imagined) episodes: the per-frame judge's network
(`gymnast.reward.judges.frames`), its output read as the step's reward scaled to [0, 1] and trained
with binary cross-entropy against that soft target. A video scores the mean over its frames after
the first, as `gymnast.reward.sim.SimDense` scores a simulator's rollout: a continuous reward, so RL
keeps the groups whose scores differ, and no threshold is chosen.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from gymnast.reward.base import RewardContext
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.sim import META_WORLD_MAX_STEP_REWARD
from gymnast.utils.device import to_device
from gymnast.world_model.metrics import pearson


class ProgressJudge(FrameJudge):
    """`Reward` whose score is the mean predicted progress (dense reward / its maximum) over the
    frames after the first."""

    backend = "progress-judge"
    binary = False

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext | None = None) -> torch.Tensor:
        steps = self.step_rewards(frames, instructions, context)
        return steps.mean(dim=1) if steps.shape[1] else torch.zeros(len(steps))

    def step_rewards(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext | None = None
                     ) -> torch.Tensor:
        """(B, T) the predicted progress of the frame each action led to; frame 0 is the start, not judged."""
        return self.frame_probabilities(frames, instructions)[:, 1:]


def progress_targets(rewards: np.ndarray) -> torch.Tensor:
    """(T + 1,) float32 targets of a video's frames from an episode's (T,) dense rewards: frame t
    follows action t - 1; the start frame, which no action led to, gets 0 and is never trained on."""
    scaled = torch.from_numpy(np.asarray(rewards, np.float32)) / META_WORLD_MAX_STEP_REWARD
    return torch.cat([torch.zeros(1), scaled.clamp(0.0, 1.0)])


def progress_loss(judge: ProgressJudge, first: torch.Tensor, frames: torch.Tensor, text: torch.Tensor,
                  targets: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """Binary cross-entropy of (N, H, W, 3) frames, beside their videos' first frames, against (N,)
    targets in [0, 1]; (loss, {"train/loss", "train/mae"})."""
    logits = judge(first, frames, text)
    targets = to_device(targets.float(), logits.device)
    loss = F.binary_cross_entropy_with_logits(logits, targets)
    error = (torch.sigmoid(logits.detach()) - targets).abs().mean()
    return loss, {"train/loss": loss.item(), "train/mae": error.item()}


def evaluate_progress(judge: ProgressJudge, videos: Sequence) -> dict:
    """How well the judge reads progress on held-out videos (each with ``frames``, ``instruction``,
    ``progress`` and ``imagined``), real and imagined apart: per-frame Pearson correlation and mean
    absolute error against the simulator's, and the Pearson correlation of whole videos' scores with
    their mean true progress (what RL compares within a group)."""
    report = {}
    for imagined in (False, True):
        chosen = [video for video in videos if video.imagined == imagined]
        if not chosen:
            continue
        predicted, truth, scores, means = [], [], [], []
        for video in chosen:
            frames = judge.frame_probabilities(video.frames[None], [video.instruction])[0, 1:]  # (T,)
            predicted.append(frames)
            truth.append(video.progress[1:])
            scores.append(frames.mean())
            means.append(video.progress[1:].mean())
        predicted, truth = torch.cat(predicted), torch.cat(truth)
        prefix = "imagined" if imagined else "real"
        report |= {f"{prefix}_frame_pearson": pearson(predicted, truth),
                   f"{prefix}_frame_mae": round(float((predicted - truth).abs().mean()), 4),
                   f"{prefix}_video_pearson": pearson(torch.stack(scores), torch.stack(means)),
                   f"{prefix}_videos": len(chosen)}
    return report
