"""A small action-conditioned video diffusion model with the call pattern of the public ones.

Cosmos-Predict2's action-conditioned checkpoint, Ctrl-World and WorldGym's DiT share one pattern:
a few context frames and a chunk of actions in, the chunk's frames out, denoised from noise in a
few steps by a transformer over patch tokens of the frames and the actions. This model keeps that
pattern (channels-first float video in [-1, 1], whole chunks only, a generator for the noise) at a
size that runs on a laptop CPU. It knows nothing of gymnast: `tiny_video_wm.gymnast_plugin` is the
adapter a user writes around a model like it.

Legend: B batch, C context frames, N actions (and frames) of a chunk, A action dimensions,
P patches per frame, F values per patch (3 * patch * patch), D width.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class VideoDiffusionConfig:
    """Sizes of the model."""

    image_size: int = 96
    """H = W of the frames."""
    patch: int = 16
    """Side of the square patches a frame is cut into (one token each)."""
    context_frames: int = 4
    """C, the past frames each call is conditioned on."""
    chunk: int = 5
    """N, the actions of one call, and the frames it returns (one per action)."""
    action_dim: int = 4
    """A."""
    width: int = 64
    """D, the transformer's width."""
    layers: int = 2
    """Transformer layers."""
    heads: int = 4
    """Attention heads."""
    denoising_steps: int = 3
    """Steps from pure noise to frames."""

    @property
    def patches(self) -> int:
        return (self.image_size // self.patch) ** 2


class VideoDiffusion(nn.Module):
    """Frames of an action chunk, denoised by a transformer over context, noisy-frame and action tokens.

    The denoiser predicts the clean frames (as a change from the last context frame) from the noisy
    ones at a noise level; sampling steps down the levels, re-noising each prediction to the next
    level with the noise it implies (deterministic DDIM), from noise drawn with the generator.
    """

    def __init__(self, config: VideoDiffusionConfig = VideoDiffusionConfig()) -> None:
        super().__init__()
        if config.image_size % config.patch:
            raise ValueError(f"image_size {config.image_size} is not a multiple of patch {config.patch}")
        self.config = config
        width, values = config.width, 3 * config.patch ** 2
        self.context_in = nn.Linear(values, width)
        self.noisy_in = nn.Linear(values, width)
        self.action_in = nn.Linear(config.action_dim, width)
        self.level_in = nn.Sequential(nn.Linear(1, width), nn.SiLU(), nn.Linear(width, width))
        tokens = (config.context_frames + config.chunk) * config.patches + config.chunk
        self.position = nn.Parameter(torch.randn(1, tokens, width) * 0.02)
        layer = nn.TransformerEncoderLayer(width, config.heads, 2 * width, dropout=0.0, batch_first=True, norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, config.layers, enable_nested_tensor=False)
        self.out = nn.Linear(width, values)
        nn.init.normal_(self.out.weight, std=0.01)  # starts near "nothing moves", as a fine-tuned model would
        nn.init.zeros_(self.out.bias)

    def patchify(self, frames: torch.Tensor) -> torch.Tensor:
        """(B, T, 3, H, W) -> (B, T, P, F)."""
        p = self.config.patch
        b, t, c, h, w = frames.shape
        grid = frames.reshape(b, t, c, h // p, p, w // p, p).permute(0, 1, 3, 5, 2, 4, 6)  # (B, T, H/p, W/p, 3, p, p)
        return grid.reshape(b, t, (h // p) * (w // p), c * p * p)

    def unpatchify(self, patches: torch.Tensor) -> torch.Tensor:
        """(B, T, P, F) -> (B, T, 3, H, W)."""
        p, size = self.config.patch, self.config.image_size
        b, t = patches.shape[:2]
        grid = patches.reshape(b, t, size // p, size // p, 3, p, p).permute(0, 1, 4, 2, 5, 3, 6)  # (B, T, 3, H/p, p, W/p, p)
        return grid.reshape(b, t, 3, size, size)

    def denoise(self, context: torch.Tensor, noisy: torch.Tensor, actions: torch.Tensor, level: float) -> torch.Tensor:
        """The clean chunk's (B, N, P, F) change from the last context frame, from the (B, C, P, F)
        context, the (B, N, P, F) noisy chunk at noise `level` and the (B, N, A) actions."""
        b, n, p, _ = noisy.shape
        level_token = self.level_in(torch.full((b, 1, 1), level, device=noisy.device, dtype=noisy.dtype))  # (B, 1, D)
        tokens = torch.cat([self.context_in(context).flatten(1, 2), (self.noisy_in(noisy) + level_token[:, None]).flatten(1, 2),
                            self.action_in(actions)], dim=1) + self.position  # (B, (C + N) * P + N, D)
        hidden = self.blocks(tokens)
        start = context.shape[1] * p
        return self.out(hidden[:, start : start + n * p]).view(b, n, p, -1)

    @torch.no_grad()
    def generate(self, context: torch.Tensor, actions: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """The chunk's frames: (B, C, 3, H, W) float context in [-1, 1] (the last is now) and
        (B, N, A) actions -> (B, N, 3, H, W) float in [-1, 1], one frame after each action."""
        config = self.config
        if tuple(context.shape[1:]) != (config.context_frames, 3, config.image_size, config.image_size):
            raise ValueError(f"context must be (B, {config.context_frames}, 3, {config.image_size}, {config.image_size}), "
                             f"got {tuple(context.shape)}")
        if tuple(actions.shape[1:]) != (config.chunk, config.action_dim):
            raise ValueError(f"actions must be (B, {config.chunk}, {config.action_dim}), got {tuple(actions.shape)}")
        tokens = self.patchify(context)  # (B, C, P, F)
        anchor = tokens[:, -1:]  # (B, 1, P, F): the frame the chunk starts from
        shape = (len(context), config.chunk, *tokens.shape[2:])
        device = generator.device if generator is not None else context.device
        noisy = torch.randn(shape, generator=generator, device=device).to(context.device)  # level 1: pure noise
        levels = torch.linspace(1.0, 0.0, config.denoising_steps + 1).tolist()
        for level, following in zip(levels, levels[1:]):
            clean = anchor + self.denoise(tokens, noisy, actions, level)  # (B, N, P, F)
            noise = (noisy - clean) / level
            noisy = clean + following * noise
        return self.unpatchify(noisy.clamp(-1.0, 1.0))
