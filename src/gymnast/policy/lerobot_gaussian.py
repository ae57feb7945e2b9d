"""LeRobot's other policies (ACT, Diffusion Policy, ...) with a Gaussian exploration head.

The policy predicts a chunk as LeRobot's ``predict_action_chunk`` does; gymnast samples each of
the first K actions from a Gaussian around it in the policy's normalised units, with a learned
standard deviation per action dimension (`ExplorationConfig`'s bounds, through the same bounded
parameterisation as the flow's noise network). The log-probability of a sampled chunk is then
exact, and GRPO trains both the policy, through the mean, and the standard deviation.

A policy whose prediction draws noise of its own (Diffusion Policy's denoising) would give a new
mean at every call and so no density; its draws are made from a fixed seed, so its mean is one
deterministic function of the observation, which LeRobot reproduces under the same seed
(`MEAN_SEED`). ACT draws nothing at inference.

Legend: B batch, P predicted actions, K executed actions, A action dimensions, N = K * A.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import torch
from torch import nn

from gymnast.policy.base import ActionSample
from gymnast.policy.flow_path import LOG_2PI, bounded_sigma, sigma_bias
from gymnast.policy.lerobot_policy import ExplorationConfig, LeRobotPolicy

MEAN_SEED = 0
"""The seed a policy's own random draws are made from when gymnast asks for its chunk."""


class LeRobotGaussianPolicy(LeRobotPolicy):
    """A LeRobot policy with a Gaussian head on its chunk, as a `gymnast.policy.base.Policy`."""

    def __init__(self, policy: nn.Module, preprocessor, postprocessor, files: dict, source: str,
                 exploration: ExplorationConfig) -> None:
        super().__init__(policy, preprocessor, postprocessor, files, source, exploration)
        self.raw_sigma = nn.Parameter(torch.full((self.action_dim,), sigma_bias(
            exploration.sigma_min, exploration.sigma_init, exploration.sigma_max)))  # (A,)

    def mean_chunk(self, batch: dict[str, Any]) -> torch.Tensor:
        # predict_action_chunk is decorated with no_grad; RL needs its gradient, so the function
        # underneath is called (the same computation, without the decorator).
        predict = type(self.policy).predict_action_chunk
        predict = getattr(predict, "__wrapped__", predict)
        device = self.device
        with torch.random.fork_rng(devices=[device] if device.type == "cuda" else []):
            torch.manual_seed(MEAN_SEED)
            chunk = predict(self.policy, batch)
        self.features.check_actions(chunk, self.source)
        return chunk

    def sigma(self) -> torch.Tensor:
        """(A,) the exploration standard deviation before temperature."""
        return bounded_sigma(self.raw_sigma, self.exploration.sigma_min, self.exploration.sigma_max)

    # -- the Policy protocol ------------------------------------------------------------------------

    @torch.no_grad()
    def sample(self, obs: torch.Tensor, instructions: Sequence[str], temperature: float = 1.0,
               generator: torch.Generator | None = None, states: torch.Tensor | None = None) -> ActionSample:
        """Actions drawn around the policy's chunk; ``tokens`` holds them in normalised units (B, N)."""
        if temperature <= 0:
            raise ValueError(f"temperature must be positive, got {temperature}; use act() for the mean chunk")
        mean = self._mean(obs, instructions, states)  # (B, K, A)
        noise = torch.randn(mean.shape, generator=generator,
                            device=generator.device if generator is not None else mean.device).to(mean.device)
        chunk = mean + temperature * self.sigma() * noise
        logp = self._log_prob(mean, chunk, temperature)[0]
        return ActionSample(actions=self.to_actions(chunk), tokens=chunk.flatten(1).cpu(), logp=logp.cpu())

    def log_prob_and_entropy(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                             temperature: float = 1.0, states: torch.Tensor | None = None
                             ) -> tuple[torch.Tensor, torch.Tensor]:
        """`log_prob`, and the (B, N) entropy of each element's Gaussian."""
        shape = (len(tokens), self.chunk_size, self.action_dim)
        if tokens.ndim != 2 or tokens.shape[1] != math.prod(shape[1:]):
            raise ValueError(f"sampled chunks must be (B, {math.prod(shape[1:])}) = (B, K * A), got {tuple(tokens.shape)}")
        mean = self._mean(obs, instructions, states)
        return self._log_prob(mean, tokens.float().view(shape).to(mean.device), temperature)

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, N) the record of a greedy rollout (env units), never trained on."""
        return actions.float().flatten(1)

    # -- helpers ------------------------------------------------------------------------------------

    def _mean(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None) -> torch.Tensor:
        """(B, K, A) the first K actions of the policy's chunk, in normalised units."""
        return self.mean_chunk(self.inputs(obs, instructions, states))[:, : self.chunk_size]

    def _log_prob(self, mean: torch.Tensor, chunk: torch.Tensor, temperature: float
                  ) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, N) log-density and entropy of `chunk` under N(mean, (temperature * sigma)^2)."""
        scale = temperature * self.sigma()  # (A,)
        logp = -0.5 * (((chunk - mean) / scale) ** 2 + LOG_2PI) - scale.log()
        entropy = (0.5 * (1 + LOG_2PI) + scale.log()).expand_as(logp)
        return logp.flatten(1), entropy.flatten(1)
