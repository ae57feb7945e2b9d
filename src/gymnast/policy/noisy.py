"""A policy made worse on purpose: another policy's greedy actions plus Gaussian noise.

Legend: B batch, H/W image size, K chunk length, A action dimensions, N = K * A tokens.

WorldGym asks whether the world model and its judge rank policies as the real world does, which
needs policies spanning a wide range of real success that all act from pixels (the scripted
experts read the simulator state, so they cannot act in imagination). Adding noise of growing
size to one trained policy's actions gives such a ladder: noise 0 is the policy itself, and
``noise=inf`` is the floor, uniformly random actions that never look at the image.

Only evaluation uses a `NoisyPolicy` (`act`); it is never trained, so `sample` and `log_prob`,
which would need the noisy actions' token distribution, are not provided.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import torch

from gymnast.policy.base import ActionSample, Policy, state_inputs

RANDOM = math.inf
"""The noise level that stands for uniformly random actions in [-1, 1] (the floor)."""


class NoisyPolicy:
    """`base`'s greedy action chunks plus N(0, noise^2) per action dimension, clipped to [-1, 1].

    Args:
        base: the policy whose greedy actions are perturbed.
        noise: standard deviation of the noise in action units (actions span [-1, 1]); 0 acts as
            `base`; ``math.inf`` (`RANDOM`) draws every action uniformly from [-1, 1] without
            calling `base`.
        seed: seed of the policy's own noise generator, so that a run repeats its draws.

    Raises:
        ValueError: a negative or NaN noise.
    """

    def __init__(self, base: Policy, noise: float, seed: int = 0) -> None:
        if not noise >= 0:  # also refuses NaN
            raise ValueError(f"noise must be >= 0 (or inf for random actions), got {noise}")
        self.base, self.noise, self.seed = base, float(noise), seed
        self.chunk_size, self.action_dim = base.chunk_size, base.action_dim
        self.state_dim = getattr(base, "state_dim", 0)
        self.generator = torch.Generator().manual_seed(seed)

    @property
    def random(self) -> bool:
        """True when the actions are uniformly random (``noise`` is infinite)."""
        return math.isinf(self.noise)

    @property
    def config(self) -> Any:
        """The base policy's architecture (evaluation reads its ``image_size``)."""
        return self.base.config

    def reseed(self, seed: int | None = None) -> None:
        """Restarts the noise stream (from `seed`, default the constructor's), so that one
        evaluation's draws do not depend on how many another evaluation used before it."""
        self.generator.manual_seed(self.seed if seed is None else seed)

    @torch.no_grad()
    def act(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, K, A) the base's greedy chunk plus noise, clipped to [-1, 1]."""
        shape = (len(obs), self.chunk_size, self.action_dim)
        if self.random:
            return torch.rand(shape, generator=self.generator) * 2 - 1
        actions = self.base.act(obs, instructions, **state_inputs(self.base, states)).float()  # (B, K, A)
        if self.noise == 0:
            return actions
        # Drawn on the CPU from our own generator (a base on another device gets it moved), so
        # the draws do not depend on the base's device or on anybody else's random state.
        noise = torch.randn(shape, generator=self.generator).to(actions.device) * self.noise
        return (actions + noise).clamp(-1.0, 1.0)

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, N) the base's tokens for the nearest bins (greedy rollouts
        record them; the executed actions are the continuous noisy ones)."""
        return self.base.chunk_tokens(actions)

    def sample(self, obs: torch.Tensor, instructions: Sequence[str], temperature: float = 1.0,
               generator: torch.Generator | None = None, states: torch.Tensor | None = None) -> ActionSample:
        raise NotImplementedError(self._untrainable("sample"))

    def log_prob(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                 temperature: float = 1.0, states: torch.Tensor | None = None) -> torch.Tensor:
        raise NotImplementedError(self._untrainable("log_prob"))

    def log_prob_and_entropy(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                             temperature: float = 1.0, states: torch.Tensor | None = None
                             ) -> tuple[torch.Tensor, torch.Tensor]:
        raise NotImplementedError(self._untrainable("log_prob_and_entropy"))

    def _untrainable(self, method: str) -> str:
        return (f"NoisyPolicy.{method}: a noisy policy only acts greedily for evaluation (act, or rollouts at "
                "temperature 0); its noisy actions have no token distribution to sample or train")

    def __repr__(self) -> str:
        return f"NoisyPolicy({type(self.base).__name__}, noise={self.noise:g}, seed={self.seed})"
