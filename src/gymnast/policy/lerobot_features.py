"""What a LeRobot policy declares it reads and writes (its config.json's ``input_features`` and
``output_features``), matched to what gymnast gives a policy and takes back.

gymnast shows a policy one camera image and the instruction at each call, and executes a chunk of
K actions of A dimensions. So exactly one VISUAL input is accepted (a second camera has no view
to be fed from); the image is resized to its declared (C, H, W) and scaled to [0, 1], as LeRobot's datasets give images; the
instruction is its ``task``. A robot state input (STATE, ENV) is refused: neither a world model
nor gymnast's policy contract carries one, and a constant in its place would be a silent lie.
The one action output must have gymnast's A dimensions (the env's, checked when the run starts),
and gymnast's chunk is the policy's ``n_action_steps``: what LeRobot executes open-loop per call.

lerobot 0.4.4's ACT and SmolVLA read ``observation.state`` even when they declare no state (for
its device, and as SmolVLA's padded state token), so a policy without one gets an empty (B, 0)
state, which is what LeRobot gives such a policy as well.

Legend: B batch, H/W image size, C channels, K chunk length, A action dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import torch
import torch.nn.functional as F

OBS_STATE = "observation.state"
ACTION = "action"
TASK = "task"


@dataclass(frozen=True)
class LeRobotFeatures:
    """The inputs and outputs of one LeRobot policy, checked against gymnast's.

    Attributes:
        image_key: the policy's one VISUAL input feature.
        image_shape: its declared (C, H, W).
        action_dim: A, the action output's size.
        chunk_size: K, the actions gymnast executes per call (the policy's n_action_steps).
        predicted: the actions the policy predicts per call (its chunk_size >= K).
    """

    image_key: str
    image_shape: tuple[int, int, int]
    action_dim: int
    chunk_size: int
    predicted: int

    @classmethod
    def of(cls, config: Any, source: str) -> LeRobotFeatures:
        """The features of a LeRobot ``PreTrainedConfig``; `source` names it in errors.

        Raises:
            ValueError: a feature gymnast cannot give or take (the message names it).
        """
        images = [key for key, feature in config.input_features.items() if _kind(feature) == "VISUAL"]
        others = {key: feature for key, feature in config.input_features.items() if _kind(feature) != "VISUAL"}
        if not images:
            raise ValueError(f"{source}: the policy declares no image input (input_features: {sorted(config.input_features)}); "
                             "gymnast shows a policy camera images")
        if len(images) > 1:
            raise ValueError(f"{source}: input feature {images[1]}: the policy reads {len(images)} cameras "
                             f"({', '.join(images)}), gymnast shows one view per call")
        for key, feature in others.items():
            raise ValueError(f"{source}: input feature {key} ({_kind(feature)}, shape {tuple(feature.shape)}): gymnast "
                             "shows a policy the camera image and the instruction only (a world model imagines no "
                             "robot state); use a policy trained without it")
        shape = tuple(config.input_features[images[0]].shape)
        if len(shape) != 3 or shape[0] != 3:
            raise ValueError(f"{source}: input feature {images[0]} has shape {shape}; gymnast's cameras give (3, H, W) colour")
        actions = dict(config.output_features)
        if list(actions) != [ACTION] or len(actions[ACTION].shape) != 1:
            raise ValueError(f"{source}: output features {({k: tuple(f.shape) for k, f in actions.items()})}: gymnast "
                             f"takes one '{ACTION}' of shape (A,)")
        chunk, predicted = int(config.n_action_steps), int(config.chunk_size)
        return cls(images[0], shape, int(actions[ACTION].shape[0]), chunk, predicted)

    @property
    def image_size(self) -> int:
        """The side of the square frames gymnast renders for this policy (its declared height)."""
        return self.image_shape[1]

    def batch(self, obs: torch.Tensor, instructions: Sequence[str]) -> dict[str, Any]:
        """(B, H, W, 3) uint8 images and B instructions -> the batch LeRobot's preprocessor takes."""
        if obs.ndim != 4 or obs.shape[-1] != 3:
            raise ValueError(f"images must be (B, H, W, 3), got {tuple(obs.shape)}")
        if len(instructions) != len(obs):
            raise ValueError(f"{len(obs)} images but {len(instructions)} instructions")
        images = obs.permute(0, 3, 1, 2).float() / 255  # (B, 3, H, W) in [0, 1], as LeRobot's datasets give
        size = self.image_shape[1:]
        if tuple(images.shape[2:]) != size:
            images = F.interpolate(images, size=size, mode="bilinear", antialias=True, align_corners=False)
        return {self.image_key: images, OBS_STATE: images.new_zeros(len(obs), 0), TASK: list(instructions)}

    def check_actions(self, actions: torch.Tensor, source: str) -> None:
        """Raises ValueError unless `actions` is (B, predicted, A), what the policy must predict."""
        if actions.ndim != 3 or actions.shape[1:] != (self.predicted, self.action_dim):
            raise ValueError(f"{source}: the policy predicted actions of shape {tuple(actions.shape)}, expected "
                             f"(B, {self.predicted}, {self.action_dim}) from its chunk_size and '{ACTION}' feature")


def _kind(feature: Any) -> str:
    """A feature's type name (VISUAL, STATE, ENV, ACTION, LANGUAGE)."""
    return getattr(feature.type, "name", str(feature.type))
