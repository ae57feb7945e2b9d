"""Actions as tokens: each dimension normalised to its range and cut into equal bins (OpenVLA).

Discrete actions give every sampled action an exact log-probability, which GRPO needs. The
tokenizer's ranges and bin count are saved with the policy, so a checkpoint decodes its own
tokens the same way forever.

Legend: A action dimensions; ``...`` any leading batch/time axes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch


@dataclass(frozen=True)
class ActionTokenizer:
    """Uniform binning of each action dimension over [low, high].

    Attributes:
        low: (A,) lower end of each dimension's range; smaller actions are clipped to it.
        high: (A,) upper end of each dimension's range; larger actions are clipped to it.
        bins: tokens per dimension (256 as in OpenVLA).
    """

    low: tuple[float, ...] = (-1.0, -1.0, -1.0, -1.0)
    high: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    bins: int = 256

    def __post_init__(self) -> None:
        if len(self.low) != len(self.high):
            raise ValueError(f"ActionTokenizer: low has {len(self.low)} dims, high has {len(self.high)}")
        if any(h <= l for l, h in zip(self.low, self.high)):
            raise ValueError(f"ActionTokenizer: every high must exceed its low, got {self.low} / {self.high}")
        if self.bins < 2:
            raise ValueError(f"ActionTokenizer: bins must be at least 2, got {self.bins}")

    @property
    def action_dim(self) -> int:
        return len(self.low)

    @property
    def bin_width(self) -> torch.Tensor:
        """(A,) width of one bin in action units; the round-trip error is at most half of it."""
        return (self._high - self._low) / self.bins

    @property
    def _low(self) -> torch.Tensor:
        return torch.tensor(self.low, dtype=torch.float32)

    @property
    def _high(self) -> torch.Tensor:
        return torch.tensor(self.high, dtype=torch.float32)

    def encode(self, actions: torch.Tensor) -> torch.Tensor:
        """(..., A) float actions -> (..., A) int64 tokens in [0, bins)."""
        self._check_dim(actions)
        unit = (actions.float().clamp(self._low, self._high) - self._low) / (self._high - self._low)
        return (unit * self.bins).long().clamp(0, self.bins - 1)

    def decode(self, tokens: torch.Tensor) -> torch.Tensor:
        """(..., A) int64 tokens -> (..., A) float32 actions at the bin centres."""
        self._check_dim(tokens)
        return self._low + (tokens.float() + 0.5) * self.bin_width

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> ActionTokenizer:
        return cls(low=tuple(data["low"]), high=tuple(data["high"]), bins=int(data["bins"]))

    def _check_dim(self, values: torch.Tensor) -> None:
        if values.shape[-1] != self.action_dim:
            raise ValueError(f"expected actions with last dimension {self.action_dim}, got shape {tuple(values.shape)}")
