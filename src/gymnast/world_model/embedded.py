"""The embedded world model: a deterministic convolutional latent video model that trains on a CPU.

Legend: B batch, C context frames, K actions, A action dimensions, H/W image size, Z latent
channels, h/w = H/8, W/8 latent grid.

    context (B, C, 3, H, W) --encoder--> z (B, Z, h, w)  + skip features at H/2 and H/4
    z --[residual conv blocks, FiLM by the action]--> z'   one latent step per action
    z' --decoder (transposed convs + skips)--> flow, rgb, alpha
    frame = alpha * rgb + (1 - alpha) * warp(last context frame, flow)
    every `reanchor_every` steps: encode the last C imagined frames as the new context
    with `action_dropout` in training, guidance w: z' = z'(no action) + w (z'(action) - z'(no action))
    grounded (`state_dim` S > 0): the FiLM condition also holds the state each frame shows (B, K, S)
    `actions_per_frame` N > 1: one latent step and one frame per chunk of N actions (the policy's
    chunk); the frames of a chunk's other actions show the last imagined frame

Why this shape (docs/world_model.md has the measurements):
- Meta-World is deterministic given the scene, and the context frames show the scene, so a
  deterministic model trained on mean squared error is the right tool at this scale; stochastic
  backends fit the same protocol later.
- Pixels move more than they change. The decoder predicts where each pixel of the last real frame
  has moved to (a flow field, relative to "now", so sampling never compounds blur) and paints only
  what the move cannot explain (alpha, rgb), such as the table behind the arm. Without the warp a
  prototype of this network settled on repeating the last frame (docs/world_model.md).
- The skip features come from the context only, so their part of the decoder's convolutions is
  computed once per rollout (`init_state`), not once per frame: the decoder's per-frame cost is a
  few small convolutions, which is what makes imagination ~10x faster than rendering on a CPU.
- The latent recurrence is trained through many steps (backpropagation through the whole
  imagined clip), so the model learns to correct its own drift instead of compounding it. Past
  that trained length a rollout re-encodes its own last frames as a fresh context
  (`reanchor_every`), which keeps whole-episode rollouts coherent.
- A model trained on experts can draw what experts do whatever the actions say (a door that opens
  under actions that miss its handle). Hiding the action in a share of training steps teaches the
  latent step what happens without one; guidance w > 1 then scales up what the action changes
  (classifier-free guidance, as in the flow backend, on the latent step).
- A video model does not know where the hand is: its arm drifts centimetres off within tens of
  steps, and it can open a door the hand never touched. A grounded model renders every frame at a
  state given from outside (the recorded one in training, a state model's in imagination,
  `gymnast.world_model.robot_state`), so where things are is decided by a model that tracks them,
  and the video model only draws them there.
- Every latent step is a chance to drift. A policy acts in chunks and reads the frame only after
  each, so a model that imagines one frame per chunk (`actions_per_frame`, as WMPO and World-Gymnast
  do) takes N times fewer autoregressive steps through an episode, and decodes N times fewer frames.
  Its latent step reads the chunk's actions in order (their embeddings, concatenated and mixed);
  actions that do not yet fill a chunk wait in the state for the next `step` call.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from gymnast.world_model.base import (ActionScale, ConfiguredWorldModel, check_action_range, check_actions, check_context,
                                      check_states, pad_context)


@dataclass(frozen=True)
class EmbeddedWorldModelConfig:
    """Architecture of the embedded world model."""

    image_size: int = 96
    """Frame height and width in pixels (a multiple of 8)."""
    context_frames: int = 2
    """Real frames the model starts from (two show which way things are moving)."""
    action_dim: int = 4
    """Action dimensions (training takes them from the dataset's ``action`` feature)."""
    action_low: tuple[float, ...] = ()
    """(A,) action that the model's input maps to -1; with `action_high`, the dataset's per-dimension
    min and max, set by training (`gymnast.data.action_stats`). Empty: actions are taken as they
    are (models saved before the normalisation, whose actions were Meta-World's, in [-1, 1])."""
    action_high: tuple[float, ...] = ()
    """(A,) action that the model's input maps to +1."""
    latent_channels: int = 64
    """Channels Z of the latent grid at 1/8 resolution."""
    widths: tuple[int, int] = (24, 48)
    """Channels of the 1/2 and 1/4 resolution encoder and decoder stages."""
    blocks: int = 2
    """Residual blocks in one latent step."""
    action_width: int = 128
    """Width of the action embedding that modulates every block."""
    bf16: bool = True
    """Imagine under bfloat16 autocast (about 2x faster on CPUs with bf16 support)."""
    reanchor_every: int = 32
    """Past this many imagined steps from one context, re-encode the state from the last imagined
    frames, as if they were real (0 = never). The latent recurrence is trained on clips of this
    length; run much longer, it drifts out of what it learned, while re-encoding keeps it in."""
    action_dropout: float = 0.0
    """Share of training steps (per rollout and action) whose action is replaced by a learned "no
    action" embedding, which only a model trained with some has; what `guidance` needs."""
    guidance: float = 1.0
    """Action guidance when imagining: each latent step is the "no action" step plus w times what
    the action changes (1 = the action's step alone; > 1 sharpens the action's effect, and computes
    the latent step twice). Changes how the weights are used, not what they are: set at load time."""
    state_dim: int = 0
    """S > 0: a grounded model, which renders every frame at the state it is given (the dataset's
    environment state where recorded, else its ``observation.state``); 0: frames follow the actions alone."""
    state_mean: tuple[float, ...] = ()
    """(S,) the training data's mean state, which the model's state input subtracts (set by training)."""
    state_std: tuple[float, ...] = ()
    """(S,) the training data's state spread, by which the model's state input divides (set by training)."""
    actions_per_frame: int = 1
    """N: actions per latent step and imagined frame (the policy's action chunk, e.g. 5). N > 1 imagines
    one frame per chunk; within a chunk the frames show the last imagined frame (a policy reads the
    frame once per chunk), and training scores the chunks' last frames alone."""

    def __post_init__(self) -> None:
        if self.image_size % 8:
            raise ValueError(f"image_size must be a multiple of 8, got {self.image_size}")
        if self.context_frames < 1 or self.blocks < 1:
            raise ValueError(f"need context_frames >= 1 and blocks >= 1, got {self.context_frames}, {self.blocks}")
        if any(w % 8 for w in (*self.widths, self.latent_channels)):
            raise ValueError(f"widths and latent_channels must be multiples of 8 (group norm), got {self.widths}, {self.latent_channels}")
        check_action_range(self.action_low, self.action_high, self.action_dim)
        if not 0 <= self.action_dropout < 1:
            raise ValueError(f"action_dropout must be in [0, 1), got {self.action_dropout}")
        if self.state_dim < 0 or len(self.state_mean) != len(self.state_std) or self.state_mean and len(self.state_mean) != self.state_dim:
            raise ValueError(f"a grounded model of {self.state_dim}-d states needs that many state_mean and state_std "
                             f"values, got {len(self.state_mean)} and {len(self.state_std)}")
        if self.actions_per_frame < 1:
            raise ValueError(f"actions_per_frame must be at least 1, got {self.actions_per_frame}")
        if self.actions_per_frame > 1 and self.state_dim:
            raise ValueError(f"a grounded model (state_dim {self.state_dim}) renders one frame per action at its "
                             f"state; actions_per_frame must be 1, got {self.actions_per_frame}")
        if self.guidance != 1 and self.action_dropout == 0:
            raise ValueError(f"guidance {self.guidance} needs a model trained with action_dropout > 0 "
                             "(it has no 'no action' step to guide from); use guidance 1")


@dataclass(frozen=True)
class LatentState:
    """Where a batch of imagined rollouts stands.

    Attributes:
        z: (B, Z, h, w) the latent grid after the last action.
        skip_fine: (B, W1, H/2, W/2) the context's contribution to the last decoder stage.
        skip_coarse: (B, W2, H/4, W/4) the context's contribution to the middle decoder stage.
        background: (B, 3, H, W) float in [0, 1], the frame the decoder warps (the last context frame).
        recent: (B, C, 3, H, W) float, the frames a re-anchor will encode: the context, replaced
            by the last C imagined frames as a re-anchor approaches.
        since_anchor: actions imagined since the state was encoded from frames.
        pending: (B, P, A) actions of a chunk not yet complete (P < N, `actions_per_frame`), or None.
    """

    z: torch.Tensor
    skip_fine: torch.Tensor
    skip_coarse: torch.Tensor
    background: torch.Tensor
    recent: torch.Tensor
    since_anchor: int = 0
    pending: torch.Tensor | None = None

    def select(self, index: torch.Tensor | slice) -> LatentState:
        """The states of some batch elements (e.g. to branch or drop rollouts)."""
        tensors = (self.z, self.skip_fine, self.skip_coarse, self.background, self.recent)
        return LatentState(*(t[index] for t in tensors), since_anchor=self.since_anchor,
                           pending=None if self.pending is None else self.pending[index])


def pixel_shuffle_2x(x: torch.Tensor) -> torch.Tensor:
    """`F.pixel_shuffle(x, 2)` as a view and one copy: about 3x faster on CPUs for bfloat16 inputs."""
    b, c, h, w = x.shape
    return x.view(b, c // 4, 2, 2, h, w).permute(0, 1, 4, 2, 5, 3).reshape(b, c // 4, 2 * h, 2 * w)


class ActionBlock(nn.Module):
    """Residual block whose hidden features are scaled and shifted by a condition vector, such as the action (FiLM)."""

    def __init__(self, channels: int, condition: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)
        self.film = nn.Linear(condition, 2 * channels)
        nn.init.zeros_(self.conv2.weight)  # each block starts as the identity: a stable recurrence
        nn.init.zeros_(self.conv2.bias)

    def forward(self, x: torch.Tensor, condition: torch.Tensor) -> torch.Tensor:
        hidden = self.conv1(F.silu(x))
        scale, shift = self.film(condition)[:, :, None, None].chunk(2, dim=1)
        return x + self.conv2(F.silu(hidden * (1 + scale) + shift))


class EmbeddedWorldModel(ConfiguredWorldModel):
    """See the module docstring; implements `gymnast.world_model.base.WorldModel`."""

    backend = "embedded"
    config_class = EmbeddedWorldModelConfig

    def __init__(self, config: EmbeddedWorldModelConfig) -> None:
        super().__init__()
        self.config = config
        fine, coarse = config.widths
        z = config.latent_channels
        self.encode_fine = nn.Sequential(nn.Conv2d(3 * config.context_frames, fine, 4, 2, 1), nn.SiLU())
        self.encode_coarse = nn.Sequential(nn.Conv2d(fine, coarse, 4, 2, 1), nn.GroupNorm(8, coarse), nn.SiLU())
        self.encode_latent = nn.Sequential(
            nn.Conv2d(coarse, z, 4, 2, 1), nn.GroupNorm(8, z), nn.SiLU(), nn.Conv2d(z, z, 3, padding=1)
        )
        self.skip_fine = nn.Conv2d(fine, fine, 1)
        self.skip_coarse = nn.Conv2d(coarse, coarse, 1)
        self.embed_action = nn.Sequential(
            nn.Linear(config.action_dim, config.action_width), nn.SiLU(), nn.Linear(config.action_width, config.action_width)
        )
        # A chunk's action embeddings, in order, mixed into one condition. It starts as their mean, so
        # a model fine-tuned from one of single actions starts from its embedding of the chunk's average.
        self.mix_chunk = None
        if config.actions_per_frame > 1:
            n, width = config.actions_per_frame, config.action_width
            self.mix_chunk = nn.Linear(n * width, width)
            with torch.no_grad():
                self.mix_chunk.weight.copy_(torch.eye(width).repeat(1, n) / n)
                self.mix_chunk.bias.zero_()
        self.blocks = nn.ModuleList(ActionBlock(z, config.action_width) for _ in range(config.blocks))
        # Only grounded models have it. Its last layer starts at zero, so a grounded fine-tune of an
        # ungrounded model starts exactly where that model was.
        self.embed_state = None
        if config.state_dim:
            self.embed_state = nn.Sequential(nn.Linear(config.state_dim, config.action_width), nn.SiLU(),
                                             nn.Linear(config.action_width, config.action_width))
            nn.init.zeros_(self.embed_state[2].weight)
            nn.init.zeros_(self.embed_state[2].bias)
            self.register_buffer("state_mean", torch.tensor(config.state_mean or (0.0,) * config.state_dim), persistent=False)
            self.register_buffer("state_std", torch.tensor(config.state_std or (1.0,) * config.state_dim), persistent=False)
        # Only models trained with action dropout have it: older runs' weights load unchanged.
        self.no_action = nn.Parameter(torch.zeros(config.action_width)) if config.action_dropout > 0 else None
        self.up_coarse = nn.ConvTranspose2d(z, coarse, 4, 2, 1)
        self.up_fine = nn.ConvTranspose2d(coarse, fine, 4, 2, 1)
        # Per output pixel: rgb, alpha and the flow (dx, dy) in [-1, 1] image units; 2x2 sub-pixels each.
        self.to_pixels = nn.Conv2d(fine, 6 * 4, 3, padding=1)
        with torch.no_grad():  # start from "nothing moves"
            self.to_pixels.weight[4 * 4 :].zero_()
            self.to_pixels.bias[4 * 4 :].zero_()
        self.scale_actions = ActionScale(config.action_low, config.action_high, config.action_dim)
        size = config.image_size
        ys, xs = torch.meshgrid(torch.linspace(-1, 1, size), torch.linspace(-1, 1, size), indexing="ij")
        self.register_buffer("identity_grid", torch.stack([xs, ys], dim=-1)[None], persistent=False)  # (1, H, W, 2)

    # The protocol -------------------------------------------------------------------------------

    @torch.inference_mode()
    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> LatentState:
        """See `WorldModel.init_state`; deterministic, so `generator` is unused."""
        check_context(context, self.image_size)
        frames = pad_context(context, self.context_frames).permute(0, 1, 4, 2, 3).float() / 255.0  # (B, C, 3, H, W)
        with self.autocast():
            return self.encode(frames)

    @property
    def state_dim(self) -> int:
        """S, the state every frame is rendered at (0: not grounded)."""
        return self.config.state_dim

    @property
    def actions_per_frame(self) -> int:
        """N, the actions of one imagined frame (1: a frame per action)."""
        return self.config.actions_per_frame

    @torch.inference_mode()
    def step(
        self, state: LatentState, actions: torch.Tensor, generator: torch.Generator | None = None,
        states: torch.Tensor | None = None,
    ) -> tuple[LatentState, torch.Tensor]:
        """See `WorldModel.step`; deterministic, so `generator` is unused. A grounded model also
        takes `states`, (B, K, S) the state after each action (`check_states`)."""
        check_actions(actions, self.action_dim, state.z.shape[0])
        check_states(states, self.state_dim, actions.shape[:2])
        with self.autocast():
            state, frames = self.imagine(state, actions.float(), None if states is None else states.float())
        # +0.5 then truncation rounds (values are >= 0); in place, as this runs once per imagined frame.
        return state, frames.permute(0, 1, 3, 4, 2).float().mul_(255.0).add_(0.5).clamp_(0, 255).to(torch.uint8)

    # Differentiable pieces, used by training -----------------------------------------------------

    def encode(self, context: torch.Tensor) -> LatentState:
        """(B, C, 3, H, W) float context in [0, 1] -> the state "now"."""
        fine = self.encode_fine(context.flatten(1, 2) * 2 - 1)  # (B, W1, H/2, W/2)
        coarse = self.encode_coarse(fine)  # (B, W2, H/4, W/4)
        return LatentState(self.encode_latent(coarse), self.skip_fine(fine), self.skip_coarse(coarse), context[:, -1], context)

    def imagine(self, state: LatentState, actions: torch.Tensor,
                states: torch.Tensor | None = None) -> tuple[LatentState, torch.Tensor]:
        """Applies (B, K, A) actions, each frame rendered at the (B, K, S) `states` of a grounded
        model; returns the new state and (B, K, 3, H, W) float frames.

        With N = `actions_per_frame` > 1 the actions join those waiting in the state, every full
        chunk of N takes one latent step and one frame, and each action's frame is the last imagined
        one by then (the previous chunk's until its own chunk completes)."""
        n, context = self.config.actions_per_frame, state.recent.shape[1]
        queued = actions if state.pending is None else torch.cat([state.pending, actions], dim=1)  # (B, P + K, A)
        embedded = self.embed_action(self.scale_actions(queued))  # (B, P + K, action_width)
        grounding = None if self.embed_state is None else self.embed_state((states - self.state_mean) / self.state_std)
        frames = []  # one per queued action
        chunks = queued.shape[1] // n
        for c in range(chunks):
            if self.config.reanchor_every and state.since_anchor >= self.config.reanchor_every:
                state = self.encode(state.recent)  # imagined frames become the new context
            z = self._latent_step(state.z, self._chunk_condition(embedded[:, c * n : (c + 1) * n]),
                                  None if grounding is None else grounding[:, c])
            frame = self._decode(z, state)  # (B, 3, H, W)
            shown = [frame] if n == 1 else [state.recent[:, -1].to(frame.dtype)] * (n - 1) + [frame]
            recent = state.recent
            # Held frames are the last one (n > 1); otherwise only the last C frames before a
            # re-anchor are ever read: keep just those.
            if n > 1 or (self.config.reanchor_every and state.since_anchor >= self.config.reanchor_every - context):
                recent = torch.cat([recent, torch.stack(shown, dim=1).to(recent.dtype)], dim=1)[:, -context:]
            state = dataclasses.replace(state, z=z, recent=recent, since_anchor=state.since_anchor + n)
            frames.extend(shown)
        waiting = queued[:, chunks * n :]
        frames.extend([state.recent[:, -1].to(embedded.dtype)] * waiting.shape[1])
        state = dataclasses.replace(state, pending=waiting if waiting.shape[1] else None)
        return state, torch.stack(frames[-actions.shape[1] :], dim=1)

    def _chunk_condition(self, embedded: torch.Tensor) -> torch.Tensor:
        """(B, N, action_width) embeddings of one chunk's actions -> (B, action_width), its condition."""
        return embedded[:, 0] if self.mix_chunk is None else self.mix_chunk(embedded.flatten(1))

    def _latent_step(self, z: torch.Tensor, action: torch.Tensor, grounding: torch.Tensor | None = None) -> torch.Tensor:
        """(B, Z, h, w) latent, (B, action_width) action embedding and, for a grounded model, the
        (B, action_width) embedding of the state to render -> the latent one action later. Action
        dropout and guidance act on the action alone: the state is what the frame must show either way."""
        ground = (lambda condition: condition) if grounding is None else (lambda condition: condition + grounding)
        if self.no_action is None:
            return self._blocks(z, ground(action))
        no_action = self.no_action.to(action.dtype).expand_as(action)
        if self.training:  # hide the action in `action_dropout` of the steps
            hidden = torch.rand(len(action), 1, device=action.device) < self.config.action_dropout
            return self._blocks(z, ground(torch.where(hidden, no_action, action)))
        if self.config.guidance == 1:
            return self._blocks(z, ground(action))
        guided, free = self._blocks(z.repeat(2, 1, 1, 1), torch.cat([ground(action), ground(no_action)])).chunk(2)
        return free + self.config.guidance * (guided - free)

    def _blocks(self, z: torch.Tensor, condition: torch.Tensor) -> torch.Tensor:
        for block in self.blocks:
            z = block(z, condition)
        return z

    def _decode(self, z: torch.Tensor, state: LatentState) -> torch.Tensor:
        x = F.silu(self.up_coarse(z) + state.skip_coarse)  # (B, W2, H/4, W/4)
        x = F.silu(self.up_fine(x) + state.skip_fine)  # (B, W1, H/2, W/2)
        x = pixel_shuffle_2x(self.to_pixels(x))  # (B, 6, H, W)
        rgb, alpha, flow = torch.sigmoid(x[:, :3]), torch.sigmoid(x[:, 3:4]), x[:, 4:].float()
        moved = F.grid_sample(state.background.float(), self.identity_grid + flow.permute(0, 2, 3, 1), mode="bilinear",
                              padding_mode="border", align_corners=True)  # (B, 3, H, W)
        return alpha * rgb + (1 - alpha) * moved.to(rgb.dtype)
