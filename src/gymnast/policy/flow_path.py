"""The stochastic flow sampler with exact path log-probabilities, shared by every flow policy.

A flow policy integrates a velocity field from Gaussian noise to an action chunk in S Euler
steps. For RL the integration becomes a Markov chain with Gaussian transitions, as VLA-RFT and
ReinFlow do: a learned noise network gives every step and every element its own standard
deviation, so

    x_0 ~ N(0, I),   x_{i+1} ~ N(mean_i(x_i), (temperature * sigma_i(x_i))^2),

and the log-density of the whole sampled path is a sum of Gaussian terms per element. A policy
supplies the transition, ``(x_i, i) -> (mean_i, sigma_i)``, in its own units and time direction;
these functions own the sampling and the density, so gymnast's flow VLA and LeRobot's flow
policies (SmolVLA) share one sampler and one log-probability.

Some elements of a policy's chunk may be deterministic (``noisy`` False): they start at 0 and
follow the mean exactly, so they add nothing to the density, but they are recomputed from the
recorded noisy elements when the density is, so the log-probability stays exact. A LeRobot flow
policy integrates padded action dimensions and actions past the executed chunk, which never act.

Legend: B batch, S integration steps, K chunk length, A action dimensions (any trailing shape).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
from torch import nn

LOG_2PI = math.log(2 * math.pi)

Transition = Callable[[torch.Tensor, int], tuple[torch.Tensor, torch.Tensor]]
"""``(x_i (B, K, A), i) -> (mean, sigma)``, both (B, K, A): step i's Gaussian before temperature."""


def bounded_sigma(raw: torch.Tensor, sigma_min: float, sigma_max: float) -> torch.Tensor:
    """The noise network's output mapped into [sigma_min, sigma_max] (a sigmoid, so never 0)."""
    return sigma_min + (sigma_max - sigma_min) * torch.sigmoid(raw)


def sigma_bias(sigma_min: float, sigma_init: float, sigma_max: float) -> float:
    """The raw value that `bounded_sigma` maps to `sigma_init`: a fresh noise network outputs it."""
    share = (sigma_init - sigma_min) / (sigma_max - sigma_min)
    return math.log(share / (1 - share))


def init_noise_head(head: nn.Linear, sigma_min: float, sigma_init: float, sigma_max: float) -> None:
    """Until RL trains it, every step's noise is sigma_init: zero weights, and the bias that maps to it."""
    nn.init.zeros_(head.weight)
    nn.init.constant_(head.bias, sigma_bias(sigma_min, sigma_init, sigma_max))


def sample_path(transition: Transition, start: torch.Tensor, steps: int, temperature: float,
                draw: Callable[[Sequence[int]], torch.Tensor], noisy: torch.Tensor | None = None) -> torch.Tensor:
    """(B, S + 1, K, A) a path of the stochastic sampler from `start` (B, K, A).

    Args:
        draw: standard normal draws of a shape, one call per step after its transition (so a
            generator's stream is consumed in a fixed order).
        noisy: bool, broadcastable to (B, K, A): the elements that get noise (None: all).
    """
    x, path = start, [start]
    for i in range(steps):
        mean, sigma = transition(x, i)
        step = temperature * sigma * draw(x.shape)
        x = mean + (step if noisy is None else torch.where(noisy, step, 0.0))
        path.append(x)
    return torch.stack(path, dim=1)


def path_log_prob(transition: Transition, path: torch.Tensor, steps: int, temperature: float,
                  noisy: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, K, A) log-density and (B, K, A) entropy of a (B, S + 1, K, A) path, summed over its steps.

    Differentiable. Where `noisy` is False the path's recorded values are ignored (the element
    follows the mean), and so are the returned values: the caller keeps the noisy elements.
    """
    start = path[:, 0]
    logp = -0.5 * (start ** 2 + LOG_2PI)  # the starting noise's density: no parameters, but part of the path's
    entropy = torch.full_like(start, 0.5 * (1 + LOG_2PI))
    x = start
    for i in range(steps):
        mean, sigma = transition(x, i)
        scale = temperature * sigma
        logp = logp - 0.5 * (((path[:, i + 1] - mean) / scale) ** 2 + LOG_2PI) - scale.log()
        entropy = entropy + 0.5 * (1 + LOG_2PI) + scale.log()
        x = path[:, i + 1] if noisy is None else torch.where(noisy, path[:, i + 1], mean)
    return logp, entropy


def integrate(transition: Transition, start: torch.Tensor, steps: int) -> torch.Tensor:
    """(B, K, A) the deterministic sampler (the ODE): every step takes its mean."""
    x = start
    for i in range(steps):
        x = transition(x, i)[0]
    return x
