"""Data-parallel training over several processes (``torchrun``) with torch DDP, one run's worth.

    torchrun --nproc_per_node N -m gymnast train-wm ...     (or sft)

The run is the run one process would make with the same global batch: every process draws the
same global batch from the same seeded sampler and trains on its own equal slice; DDP averages
the gradients, and losses that are means over a varying number of entries (masked tokens) are
re-weighted so that the average is the global batch's mean (`Parallel.global_mean`). Only the
first process (rank 0) writes checkpoints, metrics, videos and the run config; all of them
resume from the same checkpoint. On CPUs the processes talk over gloo, on GPUs over NCCL, one GPU
each (``cuda:LOCAL_RANK``).

Outside torchrun (no WORLD_SIZE, or 1) `data_parallel` yields a single process and every method
here does nothing, so the trainers have one code path.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import torch
import torch.distributed as dist
from torch import nn
from torch.nn.parallel import DistributedDataParallel


class _Loss(nn.Module):
    """A training loss of `model` as a module's forward: DDP synchronises gradients of what runs
    through its wrapper's forward, and the trainers' losses call several of a model's methods."""

    def __init__(self, model: nn.Module, loss: Callable) -> None:
        super().__init__()
        self.model, self.loss = model, loss

    def forward(self, *args, **kwargs):
        return self.loss(self.model, *args, **kwargs)


@dataclass(frozen=True)
class Parallel:
    """This process's place in the run: rank, world size and its device."""

    rank: int = 0
    world_size: int = 1
    device: torch.device = torch.device("cpu")

    @property
    def is_main(self) -> bool:
        """Whether this process writes the run (checkpoints, metrics, videos, progress)."""
        return self.rank == 0

    def share(self, batch_size: int, field: str = "batch_size") -> slice:
        """This process's slice of a global batch of `batch_size`.

        Raises:
            ValueError: the batch does not split evenly over the processes (the message names `field`).
        """
        if batch_size % self.world_size:
            raise ValueError(f"{field} {batch_size} does not split evenly over the {self.world_size} processes of "
                             f"torchrun; choose a multiple of {self.world_size}")
        size = batch_size // self.world_size
        return slice(self.rank * size, (self.rank + 1) * size)

    def loss(self, model: nn.Module, loss: Callable) -> Callable:
        """`loss(model, ...)` as a callable that synchronises gradients over the processes (DDP)."""
        if self.world_size == 1:
            return lambda *args, **kwargs: loss(model, *args, **kwargs)
        # Some parameters may not reach a given loss (e.g. a policy's RL-only heads in SFT).
        return DistributedDataParallel(_Loss(model, loss), device_ids=[self.device] if self.device.type == "cuda" else None,
                                       find_unused_parameters=True)

    def global_mean(self, loss: torch.Tensor, count: float) -> torch.Tensor:
        """A loss that is the mean over this process's `count` entries, re-weighted so that DDP's
        average over processes is the mean over all processes' entries (counts may differ, e.g.
        the valid steps of action chunks): loss * count * W / sum of counts."""
        if self.world_size == 1:
            return loss
        total = self._sum(count)
        return loss * (count * self.world_size / total) if total else loss

    def average(self, values: dict[str, float], weight: float = 1.0) -> dict[str, float]:
        """Metrics averaged over the processes, each weighted by its `weight` (its entry count)."""
        if self.world_size == 1:
            return values
        names = sorted(values)
        stacked = torch.tensor([weight, *(weight * values[name] for name in names)], dtype=torch.float64)
        dist.all_reduce(stacked)
        return {name: (stacked[i + 1] / stacked[0]).item() for i, name in enumerate(names)}

    def barrier(self) -> None:
        """Waits for every process (e.g. for rank 0's last checkpoint before the others read it)."""
        if self.world_size > 1:
            dist.barrier()

    def _sum(self, value: float) -> float:
        total = torch.tensor([float(value)], dtype=torch.float64)
        dist.all_reduce(total)
        return total.item()


@contextlib.contextmanager
def data_parallel(device: torch.device) -> Iterator[Parallel]:
    """This process's `Parallel`: under torchrun, with the process group set up (and torn down on
    the way out) and, on a GPU, the process's own ``cuda:LOCAL_RANK``; else a single process on `device`."""
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    if world_size == 1:
        yield Parallel(device=device)
        return
    rank, local_rank = int(os.environ["RANK"]), int(os.environ.get("LOCAL_RANK", "0"))
    if device.type == "cuda":
        device = torch.device("cuda", local_rank)
        torch.cuda.set_device(device)
    started = not dist.is_initialized()
    if started:
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    try:
        yield Parallel(rank, world_size, device)
    finally:
        if started:
            dist.destroy_process_group()
