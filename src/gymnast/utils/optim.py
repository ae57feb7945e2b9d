"""What the trainers share around the optimizer: the learning-rate schedule and one gradient step."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import nn


def warmup_cosine(warmup: int, total: int) -> Callable[[int], float]:
    """LR factor for `torch.optim.lr_scheduler.LambdaLR`: linear warm-up to 1, then cosine decay to 0 at `total`."""

    def factor(step: int) -> float:
        if step < warmup:
            return (step + 1) / warmup
        progress = (step - warmup) / max(1, total - warmup)
        return 0.5 * (1 + math.cos(math.pi * min(progress, 1.0)))

    return factor


def gradient_step(loss: torch.Tensor, model: nn.Module, optimizer: torch.optim.Optimizer,
                  schedule: torch.optim.lr_scheduler.LRScheduler, max_norm: float = 1.0) -> float:
    """Backpropagates `loss`, clips the gradient norm to `max_norm`, steps; returns the norm before clipping."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    norm = torch.nn.utils.clip_grad_norm_(model.parameters(), max_norm).item()
    optimizer.step()
    schedule.step()
    return norm
