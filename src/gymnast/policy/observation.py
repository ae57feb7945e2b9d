"""What every embedded policy sees: the camera images as vision tokens, read in the light of the
instruction.

Each camera's image becomes a grid of P vision tokens (`gymnast.policy.vision`) with learned
positions, modulated by the instruction's MiniLM embedding (FiLM), and one more token carries the
instruction itself: the (B, 1 + V*P, D) memory an action decoder attends to. A policy that reads
the robot's state (hand position, gripper: `PolicyArchitecture.state_dim`) has one more token,
the standardised state through a small MLP, right after the instruction's: a hand 5 cm from the
goal and one at it can look alike in a 96 px picture, but not in the state. The tokenized VLA and
the flow-matching VLA share it, so they differ only in how they turn it into actions.

Several cameras arrive side by side in one (B, H, V*W, 3) image, as the env and the datasets'
episodes carry them (`gymnast.utils.images.tile_views`). The encoder splits it back into the V
squares and runs one shared trunk over each (a convolution across the seam would mix two
unrelated pictures); the learned positions, one set per view, tell the decoder which camera a
token came from.

The encoder runs where the policy's parameters are: images and instructions come from the host
and are copied there, and what the policies hand back to the host (actions, tokens,
log-probabilities of samples) is on the host again.

Legend: B batch, H/W one view's image size, V views, P vision tokens per view, D width, S robot
state dimensions.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import torch
from torch import nn

from gymnast.config import CAMERAS
from gymnast.policy.frozen_vision import VisionMemory
from gymnast.policy.text import EMBEDDING_DIM, InstructionEncoder
from gymnast.policy.vision import make_vision_encoder, to_float_image
from gymnast.utils.images import split_views
from gymnast.utils.device import bf16_autocast, to_device


@dataclass(frozen=True)
class PolicyArchitecture:
    """What every embedded policy's architecture has: the observation encoder's and the chunk's."""

    vision: str = "cnn"
    """Image encoder: cnn (small, from scratch) or efficientnet (ImageNet EfficientNet-Lite0)."""
    width: int = 128
    """Token width D."""
    layers: int = 2
    """Transformer decoder layers of the action head."""
    heads: int = 4
    """Attention heads."""
    chunk_size: int = 5
    """Actions per chunk K (executed open-loop before the next policy call)."""
    action_dim: int = 4
    """Action dimensions A."""
    image_size: int = 96
    """Side of each camera's square input image."""
    cameras: tuple[str, ...] = ("front",)
    """The cameras the policy sees, side by side in its input image, the primary first (their names
    in the dataset it was trained on)."""
    state_dim: int = 0
    """Robot state dimensions S the policy reads beside its images (the dataset's
    ``observation.state``, the simulator's ``obs["state"]``); 0: none (`gymnast sft --robot-state`)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "cameras", tuple(self.cameras))  # a list when read back from JSON
        if not self.cameras or len(set(self.cameras)) < len(self.cameras):
            raise ValueError(f"a policy's cameras must be one or more distinct names, got {list(self.cameras)}")
        if self.state_dim < 0:
            raise ValueError(f"a policy's state_dim must be 0 (no state) or more, got {self.state_dim}")

    @property
    def env_cameras(self) -> tuple[str, ...]:
        """The simulator's views that show this policy what it was trained on (`simulator_cameras`)."""
        return simulator_cameras(self.cameras)


def simulator_cameras(cameras: Sequence[str]) -> tuple[str, ...]:
    """The simulator's views that show a policy of `cameras` what it was trained on: its cameras
    where they are the simulator's (`gymnast.config.CAMERAS`) or several; else the front view, as
    before cameras were a setting (a one-camera policy of another robot's dataset, whose camera has
    another name, acts on the front view)."""
    if len(cameras) > 1 or (cameras and all(name in CAMERAS for name in cameras)):
        return tuple(cameras)
    return ("front",)


def shared_architecture(config: PolicyArchitecture) -> dict:
    """The `PolicyArchitecture` fields of any family's config, to build another family alike."""
    return {field.name: getattr(config, field.name) for field in dataclasses.fields(PolicyArchitecture)}


class ObservationConditioned(nn.Module):
    """Base of the embedded policies: the observation encoder and its memory.

    Args:
        vision: image encoder name (`gymnast.policy.vision.VISION_ENCODERS`).
        width: token width D.
        image_size: side of each view's square image (a multiple of 16).
        pretrained_vision: load ImageNet weights where the encoder has them.
        views: cameras V, side by side in the input image.
        state_dim: robot state dimensions S read as one more token; 0 reads none
            (`gymnast.policy.base.Policy.state_dim`).
    """

    def __init__(self, vision: str, width: int, image_size: int, pretrained_vision: bool, views: int = 1,
                 state_dim: int = 0) -> None:
        super().__init__()
        grid = image_size // 16
        self.views, self.state_dim = views, state_dim
        if state_dim:
            # Standardised by the demonstrations' statistics (`standardise_states`, saved with the
            # weights): raw positions differ by centimetres, i.e. by 0.01, which a fresh layer barely sees.
            self.register_buffer("state_mean", torch.zeros(state_dim))
            self.register_buffer("state_std", torch.ones(state_dim))
            self.state_in = nn.Sequential(nn.Linear(state_dim, width), nn.SiLU(), nn.Linear(width, width))
        self.observed_shape = (image_size, views * image_size, 3)
        self.vision = make_vision_encoder(vision, width, pretrained=pretrained_vision)
        self.vision_position = nn.Parameter(torch.zeros(1, views * grid * grid, width))
        self.text_film = nn.Linear(EMBEDDING_DIM, 2 * width)
        self.text_token = nn.Linear(EMBEDDING_DIM, width)
        self.text = InstructionEncoder()
        self.vision_memory: VisionMemory | None = None  # set by `remembered_vision` while an RL step runs

    def embed_instructions(self, instructions: Sequence[str], batch: int) -> torch.Tensor:
        """(B, 384) instruction embeddings for a batch of `batch` images."""
        if len(instructions) != batch:
            raise ValueError(f"{batch} images but {len(instructions)} instructions")
        return to_device(self.text(instructions), self.vision_position.device).to(self.vision_position.dtype)

    def standardise_states(self, states: torch.Tensor) -> None:
        """Sets the state token's standardisation from (M, S) states (the demonstrations')."""
        if not self.state_dim:
            raise ValueError("this policy reads no robot state (state_dim 0)")
        states = self._checked_states(states, len(states))
        self.state_mean.copy_(states.mean(0))
        self.state_std.copy_(states.std(0).clamp(min=1e-3))  # a constant dimension (a fixed gripper) stays finite

    def memory(self, images: torch.Tensor, text: torch.Tensor, bf16_vision: bool = False,
               states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, H, V*W, 3) uint8 images, (B, 384) instruction embeddings and, for a policy that reads
        them, (B, S) robot states -> (B, 1 + V*P, D), or (B, 2 + V*P, D) with the state's token.

        `bf16_vision` runs the image encoder under bfloat16 autocast where the device computes
        bfloat16 natively: about 1.4x faster for the convolutions on such a CPU, while the small
        decoders are faster (and exact) in float32.
        """
        if tuple(images.shape[1:]) != self.observed_shape:
            raise ValueError(f"images must be (B, {', '.join(map(str, self.observed_shape))}), got {tuple(images.shape)}")
        images = to_device(images, self.vision_position.device)  # the camera's frames live on the host

        def encode(batch: torch.Tensor) -> torch.Tensor:  # (b, H, V*W, 3) -> (b*V, P, D)
            with bf16_autocast(batch.device, bf16_vision):
                return self.vision(to_float_image(split_views(batch, self.views)))

        if self.vision_memory is not None and images.device.type == "cpu":  # inside `remembered_vision`
            tokens = self.vision_memory.encode(images, bf16_vision, encode)
        else:
            tokens = encode(images)
        tokens = tokens.float().reshape(len(images), -1, tokens.shape[-1]) + self.vision_position  # (B, V*P, D)
        scale, shift = self.text_film(text).unsqueeze(1).chunk(2, dim=-1)
        tokens = tokens * (1 + scale) + shift
        first = [self.text_token(text).unsqueeze(1)]
        if self.state_dim:
            states = self._checked_states(states, len(images))
            first.append(self.state_in((states - self.state_mean) / self.state_std).unsqueeze(1))
        return torch.cat([*first, tokens], dim=1)  # (B, 1 + V*P, D), or (B, 2 + V*P, D)

    def _checked_states(self, states: torch.Tensor | None, batch: int) -> torch.Tensor:
        """(B, S) float32 states on the policy's device, or a ValueError that says what was wrong."""
        if states is None:
            raise ValueError(f"this policy reads the robot's state ({self.state_dim} dimensions) and was given none: "
                             f"pass states (B, {self.state_dim}), e.g. the simulator's obs['state']")
        if tuple(states.shape) != (batch, self.state_dim):
            raise ValueError(f"states must be ({batch}, {self.state_dim}), got {tuple(states.shape)}")
        return to_device(states, self.vision_position.device).float()
