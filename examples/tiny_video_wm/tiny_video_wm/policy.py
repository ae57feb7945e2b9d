"""A small policy of one's own that keeps gymnast's `Policy` contract.

Legend: B batch, H/W image size, K chunk, A action dimensions, N = K * A tokens, V bins.

Each action dimension of the chunk is one of V bins over [-1, 1], drawn from a categorical, so the
log-probability of a sampled chunk exists (GRPO needs it, and `log_prob` recomputes exactly the
distribution `sample` drew from). A small CNN reads the image; the instruction enters as a bag of
hashed words. ``gymnast check-policy --policy plugin:tiny-policy`` checks the contract.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from gymnast.policy.base import ActionSample


@dataclass(frozen=True)
class TinyPolicyConfig:
    """What gymnast reads off the policy (``image_size``, ``cameras``) and its sizes."""

    image_size: int = 96
    """H = W of the camera image it sees."""
    cameras: tuple[str, ...] = ("front",)
    """The simulator's views it acts on."""
    chunk_size: int = 5
    """K."""
    action_dim: int = 4
    """A."""
    bins: int = 32
    """V, per action dimension, over [-1, 1]."""
    words: int = 1024
    """Hash buckets of the instruction's words."""
    width: int = 64
    """Features of the image and of the instruction."""


class TinyPolicy(nn.Module):
    """Image and instruction -> a categorical per action token."""

    state_dim = 0  # reads no robot state

    def __init__(self, config: TinyPolicyConfig = TinyPolicyConfig()) -> None:
        super().__init__()
        self.config = config
        self.chunk_size, self.action_dim = config.chunk_size, config.action_dim
        self.vision = nn.Sequential(nn.Conv2d(3, 16, 8, stride=8), nn.ReLU(), nn.Conv2d(16, config.width, 4, stride=4),
                                    nn.ReLU(), nn.AdaptiveAvgPool2d(1), nn.Flatten())
        self.words = nn.EmbeddingBag(config.words, config.width, mode="mean")
        self.head = nn.Sequential(nn.Linear(2 * config.width, config.width), nn.ReLU(),
                                  nn.Linear(config.width, config.chunk_size * config.action_dim * config.bins))
        self.register_buffer("centres", torch.linspace(-1.0, 1.0, config.bins), persistent=False)  # (V,)

    def logits(self, obs: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        """(B, H, W, 3) uint8 and B instructions -> (B, N, V) float32 logits."""
        device = self.centres.device
        image = obs.to(device).permute(0, 3, 1, 2).float() / 255.0
        words = [[zlib.crc32(word.encode()) % self.config.words for word in text.lower().split()] or [0]
                 for text in instructions]
        offsets = torch.tensor([0] + [len(w) for w in words[:-1]], device=device).cumsum(0)
        text = self.words(torch.tensor([i for w in words for i in w], device=device), offsets)  # (B, D)
        features = torch.cat([self.vision(image), text], dim=-1)
        return self.head(features).view(len(obs), -1, self.config.bins).float()

    def _log_probs(self, obs: torch.Tensor, instructions: Sequence[str], temperature: float) -> torch.Tensor:
        if temperature <= 0:
            raise ValueError(f"temperature must be positive, got {temperature}; use act() for greedy actions")
        return torch.log_softmax(self.logits(obs, instructions) / temperature, dim=-1)  # (B, N, V)

    def _decode(self, tokens: torch.Tensor) -> torch.Tensor:
        """(B, N) bins -> (B, K, A) actions on the host."""
        return self.centres[tokens.to(self.centres.device)].view(len(tokens), self.chunk_size, self.action_dim).cpu()

    @torch.no_grad()
    def sample(self, obs: torch.Tensor, instructions: Sequence[str], temperature: float = 1.0,
               generator: torch.Generator | None = None) -> ActionSample:
        log_probs = self._log_probs(obs, instructions, temperature)
        flat = log_probs.exp().flatten(0, 1).cpu()  # (B * N, V); drawn on the host, where gymnast's generator is
        tokens = torch.multinomial(flat, 1, generator=generator).view(log_probs.shape[:2])  # (B, N)
        logp = log_probs.gather(-1, tokens.to(log_probs.device).unsqueeze(-1)).squeeze(-1)
        return ActionSample(actions=self._decode(tokens), tokens=tokens, logp=logp.cpu())

    def log_prob(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                 temperature: float = 1.0) -> torch.Tensor:
        log_probs = self._log_probs(obs, instructions, temperature)
        return log_probs.gather(-1, tokens.to(log_probs.device).unsqueeze(-1)).squeeze(-1)  # (B, N)

    def log_prob_and_entropy(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                             temperature: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
        log_probs = self._log_probs(obs, instructions, temperature)
        entropy = -(log_probs.exp() * log_probs).sum(-1)  # (B, N)
        return log_probs.gather(-1, tokens.to(log_probs.device).unsqueeze(-1)).squeeze(-1), entropy

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, N) the nearest bins."""
        distance = (actions.flatten(1).unsqueeze(-1).to(self.centres.device) - self.centres).abs()  # (B, N, V)
        return distance.argmin(-1).cpu()

    @torch.no_grad()
    def act(self, obs: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        return self._decode(self.logits(obs, instructions).argmax(-1))


def load_policy(weights: str | None = None) -> TinyPolicy:
    """gymnast's factory: ``--policy python:tiny_video_wm.policy:load_policy[@WEIGHTS]``, or
    ``--policy plugin:tiny-policy[@WEIGHTS]`` once the package is installed.

    Args:
        weights: a safetensors file of the policy's state dict; without it, weights drawn from seed 0.
    """
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        policy = TinyPolicy()
    if weights is not None:
        from safetensors.torch import load_file

        policy.load_state_dict(load_file(str(Path(weights))))
    return policy
