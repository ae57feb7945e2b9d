"""The `Policy` contract: what RL, SFT and evaluation need from a vision-language-action model.

Legend: B batch, H/W image height/width, K action-chunk length, A action dimensions,
N = K * A action tokens, D robot state dimensions.

A policy maps the current camera image and a language instruction (and, for a policy that reads
one, the robot's state) to a chunk of K actions. Its
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


def state_inputs(policy: object, states: torch.Tensor | None) -> dict[str, torch.Tensor | None]:
    """The keyword arguments that give `policy` the robot's states: ``{"states": states}`` for a
    policy that reads them (`Policy.state_dim` > 0), none for one that does not."""
    return {"states": states} if getattr(policy, "state_dim", 0) else {}


class Policy(Protocol):
    """A vision-language-action policy with tokenized action chunks.

    ``obs`` is always a (B, H, W, 3) uint8 tensor of camera images; ``instructions`` has B strings;
    ``states`` is the robot's (B, D) float32 state at each call (the simulator's ``obs["state"]``),
    None where the env has none (a world model imagines none). It is given only to a policy whose
    `state_dim` D is above 0 (`state_inputs`), which needs it (ValueError without); a policy that
    reads no state (`state_dim` 0, or no such attribute) may leave it out of its signatures.
    """

    chunk_size: int  # K
    action_dim: int  # A
    state_dim: int  # D, 0 for a policy that reads no state

    def sample(
        self,
        obs: torch.Tensor,
        instructions: Sequence[str],
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
        states: torch.Tensor | None = None,
    ) -> ActionSample:
        """Draws every token of the chunk at once, each from softmax(logits / temperature)."""
        ...

    def log_prob(
        self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor, temperature: float = 1.0,
        states: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, N) log-probabilities of the given tokens under softmax(logits / temperature).

        Differentiable; equals `ActionSample.logp` for the tokens `sample` drew at that temperature.
        """
        ...

    def log_prob_and_entropy(
        self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor, temperature: float = 1.0,
        states: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """`log_prob`, and the (B, N) entropy of each token's whole distribution (one forward pass)."""
        ...

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, N) the tokens that decode to the nearest bins."""
        ...

    def act(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, K, A) the most likely action chunk (greedy decoding), for evaluation."""
        ...
