"""What a LeRobot policy declares it reads and writes (its config.json's ``input_features`` and
``output_features``), matched to what gymnast gives a policy and takes back.

gymnast shows a policy its cameras' images and the instruction at each call, and executes a chunk
of K actions of A dimensions. Each image feature is a camera named as gymnast's datasets name them
(``observation.images.<camera>`` is ``<camera>``, another key such as ``observation.image`` is its
own name, `gymnast.data.features.camera_name`), and gymnast shows the policy those cameras: the
simulator's views of those names (a one-camera policy of another name sees the front view, as
gymnast's own policies do) or a world model's of the same names, side by side in one frame that is
split back here, one view per feature. Each image is resized to its declared
(C, H, W) and scaled to [0, 1], as LeRobot's datasets give images; the instruction is its
``task``. A robot state (``observation.state``, shape (D,)) is the env's own state at each call
where the env has one (the real world and the software simulator: hand position and gripper,
`gymnast.envs.metaworld`); a world model imagines no state, so such a policy practises with
``--env real`` or ``sim`` and is refused in imagination, by name, rather than fed a constant,
which would be a silent lie. Any other non-image input (an environment state) is refused. The one action output
must have gymnast's A dimensions (the env's, checked when the run starts), and gymnast's chunk
is the policy's ``n_action_steps``: what LeRobot executes open-loop per call.

lerobot 0.4.4's ACT and SmolVLA read ``observation.state`` even when they declare no state (for
its device, and as SmolVLA's padded state token), so a policy without one gets an empty (B, 0)
state, which is what LeRobot gives such a policy as well.

Legend: B batch, H/W image size, V cameras, C channels, K chunk length, A action dimensions,
D robot state dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import torch
import torch.nn.functional as F

from gymnast.data.features import camera_name
from gymnast.utils.images import split_views

OBS_STATE = "observation.state"
ACTION = "action"
TASK = "task"


@dataclass(frozen=True)
class LeRobotFeatures:
    """The inputs and outputs of one LeRobot policy, checked against gymnast's.

    Attributes:
        image_keys: the policy's VISUAL input features, in the order gymnast shows their views.
        image_shapes: their declared (C, H, W).
        action_dim: A, the action output's size.
        chunk_size: K, the actions gymnast executes per call (the policy's n_action_steps).
        predicted: the actions the policy predicts per call (its chunk_size >= K).
        state_dim: D, the size of its ``observation.state`` input; 0 if it reads none.
    """

    image_keys: tuple[str, ...]
    image_shapes: tuple[tuple[int, int, int], ...]
    action_dim: int
    chunk_size: int
    predicted: int
    state_dim: int = 0

    @classmethod
    def of(cls, config: Any, source: str) -> LeRobotFeatures:
        """The features of a LeRobot ``PreTrainedConfig``; `source` names it in errors.

        Raises:
            ValueError: a feature gymnast cannot give or take (the message names it).
        """
        inputs = config.input_features
        images = [key for key, feature in inputs.items() if _kind(feature) == "VISUAL"]
        others = {key: feature for key, feature in inputs.items() if _kind(feature) != "VISUAL" and key != OBS_STATE}
        if not images:
            raise ValueError(f"{source}: the policy declares no image input (input_features: {sorted(inputs)}); "
                             "gymnast shows a policy camera images")
        for key, feature in others.items():
            raise ValueError(f"{source}: input feature {key} ({_kind(feature)}, shape {tuple(feature.shape)}): gymnast "
                             f"shows a policy the camera images, the instruction and the robot's state ({OBS_STATE}) "
                             "only; use a policy trained without it")
        state = tuple(inputs[OBS_STATE].shape) if OBS_STATE in inputs else (0,)
        if len(state) != 1:
            raise ValueError(f"{source}: input feature {OBS_STATE} has shape {state}; gymnast gives a robot state of shape (D,)")
        shapes = tuple(tuple(inputs[key].shape) for key in images)
        for key, shape in zip(images, shapes):
            if len(shape) != 3 or shape[0] != 3:
                raise ValueError(f"{source}: input feature {key} has shape {shape}; gymnast's cameras give (3, H, W) colour")
        actions = dict(config.output_features)
        if list(actions) != [ACTION] or len(actions[ACTION].shape) != 1:
            raise ValueError(f"{source}: output features {({k: tuple(f.shape) for k, f in actions.items()})}: gymnast "
                             f"takes one '{ACTION}' of shape (A,)")
        chunk, predicted = int(config.n_action_steps), int(config.chunk_size)
        return cls(tuple(images), shapes, int(actions[ACTION].shape[0]), chunk, predicted, int(state[0]))

    @property
    def cameras(self) -> tuple[str, ...]:
        """The cameras whose views the policy reads, side by side in this order."""
        return tuple(camera_name(key) for key in self.image_keys)

    @property
    def image_size(self) -> int:
        """The side of the square views gymnast renders for this policy (its first camera's declared
        height; another camera of another size gets its view resized)."""
        return self.image_shapes[0][1]

    def batch(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None = None
              ) -> dict[str, Any]:
        """(B, H, V*W, 3) uint8 images (the policy's V cameras side by side), B instructions and,
        for a policy that reads one, (B, D) robot states -> the batch LeRobot's preprocessor takes.

        Raises:
            ValueError: shapes that do not fit, or no states for a policy that reads them (named).
        """
        views = len(self.image_keys)
        if obs.ndim != 4 or obs.shape[-1] != 3 or obs.shape[2] % views:
            cameras = f"{views} cameras side by side, " if views > 1 else ""
            raise ValueError(f"images must be (B, H, W, 3) ({cameras}W a multiple of {views}), got {tuple(obs.shape)}")
        if len(instructions) != len(obs):
            raise ValueError(f"{len(obs)} images but {len(instructions)} instructions")
        images = split_views(obs, views).permute(0, 3, 1, 2).float() / 255  # (B*V, 3, H, W) in [0, 1], as LeRobot's datasets give
        images = images.unflatten(0, (len(obs), views))  # (B, V, 3, H, W)
        batch: dict[str, Any] = {}
        for index, (key, shape) in enumerate(zip(self.image_keys, self.image_shapes)):
            view = images[:, index]
            if tuple(view.shape[2:]) != shape[1:]:
                view = F.interpolate(view, size=shape[1:], mode="bilinear", antialias=True, align_corners=False)
            batch[key] = view
        return batch | {OBS_STATE: self._states(states, len(obs)), TASK: list(instructions)}

    def _states(self, states: torch.Tensor | None, count: int) -> torch.Tensor:
        """(B, D) float32 robot states for the policy, or (B, 0) for one that reads none."""
        if not self.state_dim:
            return torch.zeros(count, 0)
        if states is None:
            raise ValueError(f"the policy reads {OBS_STATE} ({self.state_dim},), but this env gives no robot state "
                             "(a world model imagines images only): use it with --env real or sim")
        if tuple(states.shape) != (count, self.state_dim):
            raise ValueError(f"the policy reads {OBS_STATE} of shape ({self.state_dim},), got states "
                             f"{tuple(states.shape)} for {count} observations")
        return states.float()

    def check_actions(self, actions: torch.Tensor, source: str) -> None:
        """Raises ValueError unless `actions` is (B, predicted, A), what the policy must predict."""
        if actions.ndim != 3 or actions.shape[1:] != (self.predicted, self.action_dim):
            raise ValueError(f"{source}: the policy predicted actions of shape {tuple(actions.shape)}, expected "
                             f"(B, {self.predicted}, {self.action_dim}) from its chunk_size and '{ACTION}' feature")


def folder_cameras(config: dict) -> tuple[str, ...]:
    """`LeRobotFeatures.cameras` read off a pretrained_model folder's config.json (as a dict),
    without building the policy."""
    return tuple(camera_name(key) for key, feature in config.get("input_features", {}).items()
                 if feature.get("type") == "VISUAL")


def _kind(feature: Any) -> str:
    """A feature's type name (VISUAL, STATE, ENV, ACTION, LANGUAGE)."""
    return getattr(feature.type, "name", str(feature.type))
