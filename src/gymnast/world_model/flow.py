"""The flow world model: a generative latent video model that samples one frame per action.

Legend: B batch, C context frames, K actions, F future frames of a training clip, N = B * F
training samples, A action dimensions, H/W image size, Z latent channels, h/w = H/8, W/8 latent
grid, S sampling steps, tau flow time in [0, 1] (0 noise, 1 data), sigma a context noise level.

    frame (B, 3, H, W) --encoder--> z (B, Z, h, w) in [-1, 1]
    z + the anchor's features --decoder--> frame       anchor: the last real frame, encoded once
    next latent: x ~ N(0, I), then S Euler steps of x += v(x, tau | noised z_{t-C..t-1}, sigma, a_t) / S
    frame_t = decode(x), and x joins the context latents

Why this shape (docs/world_model.md has the measurements):
- Generative. The embedded model, trained on mean squared error, paints the average of what it
  cannot pin down (a puck that may or may not be pushed, an arm a few pixels either way) as blur,
  and the average of "succeeds" and "fails" can look like success. A flow-matching model samples
  one outcome instead; repeated rollouts from one scene differ where the model is unsure.
- Latent. Flow matching over 96 x 96 pixels costs S full-resolution network passes per frame; over
  a 12 x 12 grid of Z channels the velocity network is a few small convolutions, and only the
  decoder runs at full resolution, once per frame (as in the embedded model).
- Anchor features. The decoder also sees features of the last real frame (computed once per
  rollout), so the static scene stays sharp and the latent need only carry what moves. Trained
  with anchors at most F + C - 1 frames old, it also copies the anchor's arm into long rollouts
  (measured in docs/world_model.md).
- Per-frame noise levels (diffusion forcing). In training every context latent gets noise of its
  own random level sigma (up to `max_context_noise`), which the network is told; while imagining,
  the generated context latents are noised at `context_noise`. The network thus learns not to
  trust its context exactly, so that its own slightly-off samples need not compound into drift
  (at the CPU budget they still do by h32: docs/world_model.md).
- Classifier-free guidance on actions. The action is hidden for `action_dropout` of training
  samples; guidance w != 1 samples with v_free + w (v_action - v_free), at twice the cost.
- The autoencoder is trained by reconstruction, the velocity network by flow matching on the
  encoder's latents with gradients stopped (otherwise the flow loss would pull every latent
  towards one constant, which is trivially predictable). Both in one run, one optimizer.
- Every random draw takes the contract's generator: one seed, one rollout.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from gymnast.world_model.base import ActionScale, ConfiguredWorldModel, check_action_range, check_actions, check_context, pad_context
from gymnast.world_model.data import ClipBatch
from gymnast.world_model.embedded import ActionBlock, pixel_shuffle_2x
from gymnast.world_model.metrics import moving_mask, to_unit_float

_TIME_FREQUENCIES = 6  # sin/cos features of tau at frequencies pi * 2^k


@dataclass(frozen=True)
class FlowWorldModelConfig:
    """Architecture and sampling of the flow world model."""

    image_size: int = 96
    """Frame height and width in pixels (a multiple of 8)."""
    context_frames: int = 2
    """Latents the velocity network conditions on (the last C frames, real or imagined)."""
    action_dim: int = 4
    """Action dimensions (training takes them from the dataset's ``action`` feature)."""
    action_low: tuple[float, ...] = ()
    """(A,) action that the network's input maps to -1; with `action_high`, the dataset's
    per-dimension min and max, set by training. Empty: actions are taken as they are."""
    action_high: tuple[float, ...] = ()
    """(A,) action that the network's input maps to +1."""
    latent_channels: int = 8
    """Channels Z of the latent grid at 1/8 resolution."""
    widths: tuple[int, int] = (32, 64)
    """Channels of the autoencoder's 1/2 and 1/4 resolution stages."""
    width: int = 96
    """Channels of the velocity network (on the 1/8 grid)."""
    blocks: int = 3
    """Residual blocks of the velocity network."""
    condition_width: int = 128
    """Width of the embedding of the action, the flow time and the context noise levels."""
    sample_steps: int = 4
    """Euler steps S from noise to a latent when imagining (each one velocity-network pass)."""
    context_noise: float = 0.1
    """Noise level sigma of the context latents when imagining (within training's range)."""
    max_context_noise: float = 0.3
    """Training draws each context latent's noise level uniformly from [0, this]."""
    action_dropout: float = 0.1
    """Share of training samples whose action is hidden (what classifier-free guidance needs)."""
    guidance: float = 1.0
    """Classifier-free guidance scale on the action when imagining (1 = none, one pass per step)."""
    bf16: bool = True
    """Run under bfloat16 autocast (about 2x faster on CPUs with bf16 support)."""

    def __post_init__(self) -> None:
        if self.image_size % 8:
            raise ValueError(f"image_size must be a multiple of 8, got {self.image_size}")
        if self.context_frames < 1 or self.blocks < 1 or self.sample_steps < 1:
            raise ValueError(f"need context_frames, blocks and sample_steps >= 1, got "
                             f"{self.context_frames}, {self.blocks}, {self.sample_steps}")
        if any(w % 8 for w in (*self.widths, self.width)):
            raise ValueError(f"widths and width must be multiples of 8 (group norm), got {self.widths}, {self.width}")
        if not 0 <= self.context_noise <= self.max_context_noise:
            raise ValueError(f"need 0 <= context_noise <= max_context_noise, got {self.context_noise}, {self.max_context_noise}")
        check_action_range(self.action_low, self.action_high, self.action_dim)


@dataclass(frozen=True)
class FlowState:
    """Where a batch of imagined rollouts stands.

    Attributes:
        latents: (B, C, Z, h, w) float32, the latents of the last C frames (real, then imagined).
        skip_fine: (B, W1, H/2, W/2) the anchor's contribution to the decoder's last stage.
        skip_coarse: (B, W2, H/4, W/4) the anchor's contribution to the decoder's middle stage.
    """

    latents: torch.Tensor
    skip_fine: torch.Tensor
    skip_coarse: torch.Tensor

    def select(self, index: torch.Tensor | slice) -> FlowState:
        """The states of some batch elements (e.g. to branch or drop rollouts)."""
        return FlowState(self.latents[index], self.skip_fine[index], self.skip_coarse[index])


class FlowWorldModel(ConfiguredWorldModel):
    """See the module docstring; implements `gymnast.world_model.base.WorldModel`."""

    backend = "flow"
    config_class = FlowWorldModelConfig

    def __init__(self, config: FlowWorldModelConfig) -> None:
        super().__init__()
        self.config = config
        fine, coarse = config.widths
        z, width = config.latent_channels, config.width
        self.encode_fine = nn.Sequential(nn.Conv2d(3, fine, 4, 2, 1), nn.SiLU())
        self.encode_coarse = nn.Sequential(nn.Conv2d(fine, coarse, 4, 2, 1), nn.GroupNorm(8, coarse), nn.SiLU())
        self.encode_latent = nn.Sequential(
            nn.Conv2d(coarse, coarse, 4, 2, 1), nn.GroupNorm(8, coarse), nn.SiLU(), nn.Conv2d(coarse, z, 3, padding=1), nn.Tanh()
        )
        self.skip_fine = nn.Conv2d(fine, fine, 1)
        self.skip_coarse = nn.Conv2d(coarse, coarse, 1)
        self.decode_latent = nn.Sequential(nn.Conv2d(z, coarse, 3, padding=1), nn.SiLU())
        self.up_coarse = nn.ConvTranspose2d(coarse, coarse, 4, 2, 1)
        self.up_fine = nn.ConvTranspose2d(coarse, fine, 4, 2, 1)
        self.to_pixels = nn.Conv2d(fine, 3 * 4, 3, padding=1)  # rgb of 2 x 2 sub-pixels
        # The condition: the action (zeros when hidden), a hidden-action flag, tau's features, the C noise levels.
        features = config.action_dim + 1 + 2 * _TIME_FREQUENCIES + config.context_frames
        self.embed = nn.Sequential(nn.Linear(features, config.condition_width), nn.SiLU(),
                                   nn.Linear(config.condition_width, config.condition_width))
        self.velocity_in = nn.Conv2d(z * (config.context_frames + 1), width, 3, padding=1)
        self.blocks = nn.ModuleList(ActionBlock(width, config.condition_width) for _ in range(config.blocks))
        self.velocity_out = nn.Sequential(nn.GroupNorm(8, width), nn.SiLU(), nn.Conv2d(width, z, 3, padding=1))
        self.scale_actions = ActionScale(config.action_low, config.action_high, config.action_dim)
        self.register_buffer("frequencies", math.pi * 2.0 ** torch.arange(_TIME_FREQUENCIES), persistent=False)

    # The protocol -------------------------------------------------------------------------------

    @torch.inference_mode()
    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> FlowState:
        """See `WorldModel.init_state`; encoding real frames draws nothing, so `generator` is unused."""
        check_context(context, self.image_size)
        frames = to_unit_float(pad_context(context, self.context_frames))  # (B, C, 3, H, W)
        with self.autocast():
            latents = self.encode(frames.flatten(0, 1)).float().unflatten(0, frames.shape[:2])  # (B, C, Z, h, w)
            skip_fine, skip_coarse = self.anchor(frames[:, -1])
        return FlowState(latents, skip_fine, skip_coarse)

    @torch.inference_mode()
    def step(self, state: FlowState, actions: torch.Tensor, generator: torch.Generator | None = None) -> tuple[FlowState, torch.Tensor]:
        """See `WorldModel.step`: samples one frame per action, drawing noise from `generator`."""
        check_actions(actions, self.action_dim, state.latents.shape[0])
        frames = []
        with self.autocast():
            for k in range(actions.shape[1]):
                z = self.sample_latent(state.latents, self.scale_actions(actions[:, k].float()), generator)  # (B, Z, h, w)
                frames.append(self.decode(z, state.skip_fine, state.skip_coarse))
                state = dataclasses.replace(state, latents=torch.cat([state.latents[:, 1:], z[:, None]], dim=1))
        # +0.5 then truncation rounds (values are >= 0).
        return state, torch.stack(frames, 1).permute(0, 1, 3, 4, 2).float().mul_(255.0).add_(0.5).clamp_(0, 255).to(torch.uint8)

    # The pieces ---------------------------------------------------------------------------------

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) float frames in [0, 1] -> (B, Z, h, w) latents in [-1, 1]."""
        return self.encode_latent(self.encode_coarse(self.encode_fine(frames * 2 - 1)))

    def anchor(self, frame: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, 3, H, W) float anchor frame -> its (fine, coarse) contributions to the decoder."""
        fine = self.encode_fine(frame * 2 - 1)
        return self.skip_fine(fine), self.skip_coarse(self.encode_coarse(fine))

    def decode(self, z: torch.Tensor, skip_fine: torch.Tensor, skip_coarse: torch.Tensor) -> torch.Tensor:
        """(B, Z, h, w) latents and the anchor's features -> (B, 3, H, W) frames in [0, 1]."""
        x = F.silu(self.up_coarse(self.decode_latent(z)) + skip_coarse)  # (B, W2, H/4, W/4)
        x = F.silu(self.up_fine(x) + skip_fine)  # (B, W1, H/2, W/2)
        return torch.sigmoid(pixel_shuffle_2x(self.to_pixels(x)))

    def velocity(self, x: torch.Tensor, tau: torch.Tensor, context: torch.Tensor, sigma: torch.Tensor,
                 actions: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
        """The flow's velocity at x.

        Args:
            x: (B, Z, h, w) the latent being generated, at flow time tau.
            tau: (B,) flow time.
            context: (B, C, Z, h, w) noised context latents.
            sigma: (B, C) their noise levels.
            actions: (B, A) the action leading to the generated frame.
            keep: (B,) bool, False where the action is hidden.
        """
        angles = tau[:, None].float() * self.frequencies  # (B, 6)
        shown = keep[:, None].to(actions.dtype)
        condition = self.embed(torch.cat([actions * shown, 1 - shown, angles.sin(), angles.cos(), sigma], dim=1))
        h = self.velocity_in(torch.cat([x, context.flatten(1, 2)], dim=1))
        for block in self.blocks:
            h = block(h, condition)
        return self.velocity_out(h)

    def sample_latent(self, latents: torch.Tensor, actions: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """Samples the next (B, Z, h, w) latent after (B, C, Z, h, w) latents under (B, A) actions."""
        config, b = self.config, latents.shape[0]
        device = latents.device
        sigma = torch.full((b, config.context_frames), config.context_noise, device=device)  # (B, C)
        context = latents + config.context_noise * _normal(latents.shape, generator, device)
        x = _normal(latents[:, 0].shape, generator, device)  # (B, Z, h, w) at tau = 0
        keep = torch.ones(b, dtype=torch.bool, device=device)
        for i in range(config.sample_steps):
            tau = torch.full((b,), i / config.sample_steps, device=device)
            if config.guidance == 1.0:
                v = self.velocity(x, tau, context, sigma, actions, keep)
            else:  # the action-conditioned and the action-free velocity in one batched pass
                both = self.velocity(x.repeat(2, 1, 1, 1), tau.repeat(2), context.repeat(2, 1, 1, 1, 1), sigma.repeat(2, 1),
                                     actions.repeat(2, 1), torch.cat([keep, ~keep]))
                shown, hidden = both.chunk(2)
                v = hidden + config.guidance * (shown - hidden)
            x = x + v.float() / config.sample_steps
        return x.clamp(-1, 1)


def _normal(shape: torch.Size, generator: torch.Generator | None, device: torch.device) -> torch.Tensor:
    """Standard normal noise from `generator` (on its device), moved to `device`."""
    where = generator.device if generator is not None else device
    return torch.randn(shape, generator=generator, device=where).to(device)


def flow_clip_loss(model: FlowWorldModel, clips: ClipBatch, generator: torch.Generator,
                   moving_weight: float = 0.0) -> tuple[torch.Tensor, dict[str, float]]:
    """Reconstruction plus flow-matching loss on a batch of clips; (loss, metrics).

    Every frame of the clip is encoded and decoded (with the last context frame as the anchor);
    every future frame is a flow-matching target given the C latents before it (teacher forcing,
    with noised context), so one clip of F future frames gives F flow samples. All noise comes
    from `generator` (on the host), so a resumed run draws what the uninterrupted one did.

    Args:
        model: the flow model.
        clips: C context and F future frames with their F actions (on the model's device).
        generator: the host generator of training draws (the trainer's sampler).
        moving_weight: extra weight of moving pixels in the reconstruction (see `train.frame_loss`).

    Returns:
        The loss and {"train/loss", "train/recon_loss", "train/flow_loss", "train/psnr": the
        autoencoder's reconstruction PSNR}.
    """
    config = model.config
    c = config.context_frames
    frames = to_unit_float(torch.cat([clips.context, clips.future], dim=1))  # (B, C+F, 3, H, W)
    b, t = frames.shape[:2]
    with model.autocast():
        skip_fine, skip_coarse = model.anchor(frames[:, c - 1])
        latents = model.encode(frames.flatten(0, 1))  # (B*(C+F), Z, h, w)
        decoded = model.decode(latents, skip_fine.repeat_interleave(t, 0), skip_coarse.repeat_interleave(t, 0))
    error = (decoded.float().unflatten(0, (b, t)) - frames).square()  # (B, C+F, 3, H, W)
    recon = error.mean()
    if moving_weight:
        weight = 1 + moving_weight * moving_mask(frames, frames[:, c - 1 : c]).float()  # (B, C+F, 1, H, W)
        recon = (error * weight).mean() / weight.mean()

    latents = latents.detach().float().unflatten(0, (b, t))  # (B, C+F, Z, h, w)
    f = t - c
    target = latents[:, c:].flatten(0, 1)  # (N, Z, h, w)
    context = latents.unfold(1, c, 1)[:, :f].movedim(-1, 2).flatten(0, 1)  # (N, C, Z, h, w): the C latents before each target
    n, device = target.shape[0], target.device
    draw = lambda *shape: torch.rand(shape, generator=generator).to(device)  # noqa: E731
    sigma = draw(n, c) * config.max_context_noise  # (N, C)
    context = context + sigma[:, :, None, None, None] * _normal(context.shape, generator, torch.device("cpu")).to(device)
    tau = draw(n)
    noise = _normal(target.shape, generator, torch.device("cpu")).to(device)
    x = (1 - tau[:, None, None, None]) * noise + tau[:, None, None, None] * target
    keep = draw(n) >= config.action_dropout
    with model.autocast():
        v = model.velocity(x, tau, context, sigma, model.scale_actions(clips.actions.flatten(0, 1).float()), keep)
    flow = (v.float() - (target - noise)).square().mean()
    loss = recon + flow
    mse = error.mean().item()
    return loss, {"train/loss": loss.item(), "train/recon_loss": recon.item(), "train/flow_loss": flow.item(),
                  "train/psnr": -10 * math.log10(max(mse, 1e-10))}
