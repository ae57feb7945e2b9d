"""The `Policy` contract: what RL, SFT and evaluation need from a vision-language-action model.

Legend: B batch, H/W image height/width, K action-chunk length, A action dimensions,
N = K * A action tokens.

A policy maps the current camera image and a language instruction to a chunk of K actions. Its
actions are discrete tokens (bins), so the log-probability of every sampled action exists: GRPO
needs it, and `log_prob` must agree exactly with the distribution `sample` draws from.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

import torch


@dataclass(frozen=True)
class ActionSample:
    """One sampled action chunk per batch element.

    Attributes:
        actions: (B, K, A) float32 actions in environment units.
        tokens: (B, N) int64 the sampled bin of every action dimension, chunk-major.
        logp: (B, N) float32 log-probability of each sampled token under the sampling
            distribution (after temperature).
    """

    actions: torch.Tensor
    tokens: torch.Tensor
    logp: torch.Tensor


class Policy(Protocol):
    """A vision-language-action policy with tokenized action chunks.

    ``obs`` is always a (B, H, W, 3) uint8 tensor of camera images; ``instructions`` has B strings.
    """

    chunk_size: int  # K
    action_dim: int  # A

    def sample(
        self,
        obs: torch.Tensor,
        instructions: Sequence[str],
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
    ) -> ActionSample:
        """Draws every token of the chunk at once, each from softmax(logits / temperature)."""
        ...

    def log_prob(
        self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor, temperature: float = 1.0
    ) -> torch.Tensor:
        """(B, N) log-probabilities of the given tokens under softmax(logits / temperature).

        Differentiable; equals `ActionSample.logp` for the tokens `sample` drew at that temperature.
        """
        ...

    def log_prob_and_entropy(
        self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor, temperature: float = 1.0
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """`log_prob`, and the (B, N) entropy of each token's whole distribution (one forward pass)."""
        ...

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, N) the tokens that decode to the nearest bins."""
        ...

    def act(self, obs: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        """(B, K, A) the most likely action chunk (greedy decoding), for evaluation."""
        ...
