"""An imitation loss on expert demonstrations beside GRPO's: VLA-RFT's auxiliary loss.

VLA-RFT trains its flow policy with GRPO plus a small flow-matching loss on expert actions, so
that practice cannot carry the policy far from behaviour it knows works. Here every policy family
brings its own imitation loss (`imitation_loss`: the flow-matching loss for the flow VLA, the
token cross-entropy for the tokenized one), and the term can be gated by the policy's KL to the
policy it started from: it then pulls only once the policy has drifted.

Legend: M demonstration samples, B batch, K chunk length, A action dimensions.
"""

from __future__ import annotations

from pathlib import Path

import torch

from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.policy.base import state_inputs
from gymnast.policy.sft import DEMO_BEHAVIOURS, DemoSet, load_demos, select_demos

DEMOS_PER_TASK = 10
"""Demonstrations per task the anchor draws from (what the SFT presets imitate)."""


class ImitationAnchor:
    """Draws expert samples and returns the weighted imitation loss of a policy on them.

    Args:
        demos: the demonstration samples.
        coef: the loss's weight.
        kl_gate: add it only while the step's KL to the starting policy exceeds this (0: always).
        batch_size: samples per update.
    """

    def __init__(self, demos: DemoSet, coef: float, kl_gate: float, batch_size: int) -> None:
        self.demos, self.coef, self.kl_gate, self.batch_size = demos, coef, kl_gate, batch_size

    @classmethod
    def from_dataset(cls, data: Path, tasks: tuple[str, ...], chunk_size: int, coef: float, kl_gate: float,
                     batch_size: int, keys: FeatureKeys = FeatureKeys(),
                     cameras: tuple[str, ...] | None = None) -> ImitationAnchor:
        """The anchor on the first successful expert episodes of `tasks` in `data` (at most
        `DEMOS_PER_TASK` each, and at least one), seen through `cameras` where the policy has
        several (default: the dataset's first camera).

        Raises:
            ValueError: a task has no successful expert episode in `data`.
        """
        dataset = EpisodeDataset(data, cameras=cameras, keys=keys)
        counts = {task: sum(1 for info in dataset.episodes if info.task == task and info.success
                            and info.behaviour in DEMO_BEHAVIOURS) for task in tasks}
        lacking = [task for task, count in counts.items() if count == 0]
        if lacking:
            raise ValueError(f"{data} has no successful expert episode of {', '.join(lacking)} to imitate")
        per_task = min(DEMOS_PER_TASK, *counts.values())
        indices = select_demos(dataset, per_task, ",".join(tasks))
        return cls(load_demos(dataset, indices, chunk_size), coef, kl_gate, batch_size)

    def active(self, kl: float | None) -> bool:
        """Whether the loss applies at a step whose KL to the starting policy is `kl` (None: unknown)."""
        return self.kl_gate <= 0 or (kl is not None and kl > self.kl_gate)

    def loss(self, policy, generator: torch.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        """`coef` times the policy's imitation loss on a random batch of demonstrations."""
        batch = torch.randint(0, len(self.demos.images), (self.batch_size,), generator=generator)
        texts = [self.demos.instructions[i] for i in self.demos.instruction[batch].tolist()]
        states = state_inputs(policy, None if self.demos.states is None else self.demos.states[batch])
        loss, _ = policy.imitation_loss(self.demos.images[batch], texts, self.demos.chunks[batch],
                                        self.demos.valid[batch], generator=generator, **states)
        return self.coef * loss, {"train/imitation_loss": loss.item()}
