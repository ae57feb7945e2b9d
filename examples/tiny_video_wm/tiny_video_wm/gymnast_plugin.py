"""The adapter: `VideoDiffusion` as a gymnast `WorldModel`, and the factory gymnast calls.

Legend: B batch, C context frames, K actions of one `step` call, N actions of one model call,
H/W image size, A action dimensions.

What the adapter does is what any wrapper of an outside video model does:

- frames: gymnast's are uint8 (B, T, H, W, 3), channels last; the model's float (B, T, 3, H, W)
  in [-1, 1]. Converted both ways at the seam.
- context: gymnast may start from a single real frame; the model wants C. The first frame is
  repeated in front (`pad_context`), as if the robot had stood still.
- chunks: gymnast steps any K actions; the model takes whole chunks of N. K is cut into chunks, and
  a last, partial one is padded with its last action and only its first frames are kept.
- state: the last C frames, a new tensor every step (never written in place), so rollouts can
  branch from one state.
- randomness: the generator gymnast passes goes to the model's noise, so runs are reproducible.
- memory: `offload` and `onload` move the weights off the GPU while gymnast trains the policy.

``gymnast check-wm --wm plugin:tiny-video`` checks all of this.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from gymnast.world_model.base import check_actions, check_context, pad_context
from tiny_video_wm.diffusion import VideoDiffusion, VideoDiffusionConfig


@dataclass(frozen=True)
class VideoState:
    """Where a batch of rollouts stands: (B, C, 3, H, W) float in [-1, 1], the last C frames."""

    frames: torch.Tensor


class TinyVideoWorldModel(nn.Module):
    """`gymnast.world_model.base.WorldModel` around a `VideoDiffusion`.

    Args:
        model: the video model.
    """

    def __init__(self, model: VideoDiffusion) -> None:
        super().__init__()
        self.model = model
        self.context_frames = model.config.context_frames
        self.image_size = model.config.image_size
        self.action_dim = model.config.action_dim
        self._home: torch.device | None = None  # where `onload` brings the weights back to

    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> VideoState:
        """See `WorldModel.init_state`: (B, C', H, W, 3) uint8, any C' >= 1."""
        check_context(context, self.image_size)
        frames = pad_context(context, self.context_frames)  # (B, C, H, W, 3)
        return VideoState(frames.permute(0, 1, 4, 2, 3).float() / 127.5 - 1.0)

    @torch.no_grad()
    def step(self, state: VideoState, actions: torch.Tensor,
             generator: torch.Generator | None = None) -> tuple[VideoState, torch.Tensor]:
        """See `WorldModel.step`: (B, K, A) actions -> (B, K, H, W, 3) uint8 frames, one model call per chunk."""
        check_actions(actions, self.action_dim, len(state.frames))
        chunk = self.model.config.chunk
        context, imagined = state.frames, []
        for part in actions.float().split(chunk, dim=1):  # (B, n, A), n <= N
            n = part.shape[1]
            whole = torch.cat([part, part[:, -1:].expand(-1, chunk - n, -1)], dim=1)  # (B, N, A)
            frames = self.model.generate(context, whole, generator)[:, :n]  # (B, n, 3, H, W)
            context = torch.cat([context, frames], dim=1)[:, -self.context_frames :]
            imagined.append(frames)
        video = torch.cat(imagined, dim=1)  # (B, K, 3, H, W)
        pixels = ((video + 1.0) * 127.5).round().clamp(0, 255).to(torch.uint8)
        return VideoState(context), pixels.permute(0, 1, 3, 4, 2).contiguous()

    def offload(self) -> None:
        """Frees the GPU's memory for gymnast's training step: the weights wait on the host."""
        self._home = next(self.parameters()).device
        self.to("cpu")
        if self._home.type == "cuda":
            torch.cuda.empty_cache()

    def onload(self) -> None:
        """Brings the weights back to where they were before `offload`."""
        if self._home is not None:
            self.to(self._home)


def load_world_model(weights: str | None = None) -> TinyVideoWorldModel:
    """gymnast's factory: ``--wm python:tiny_video_wm.gymnast_plugin:load_world_model[@WEIGHTS]``,
    or ``--wm plugin:tiny-video[@WEIGHTS]`` once the package is installed.

    Args:
        weights: a safetensors file of `VideoDiffusion`'s state dict; without it, weights drawn from
            seed 0 (the same every time, and gymnast's own random streams untouched).
    """
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        model = VideoDiffusion(VideoDiffusionConfig())
    if weights is not None:
        from safetensors.torch import load_file

        model.load_state_dict(load_file(str(Path(weights))))
    return TinyVideoWorldModel(model)
