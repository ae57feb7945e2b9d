"""The named camera views of a Meta-World scene (`gymnast.config.CAMERAS`) and where each one is.

- ``front``: the fixed free camera `EnvConfig.camera`, which frames the arm, the objects and the
  goal together, at about 1 px per cm at 96 px. It cannot tell "above the object" from "a few
  centimetres in front of it".
- ``gripper``: a wrist camera. Meta-World's hand translates but never rotates, so a camera kept at
  a fixed offset and orientation from the gripper's centre is rigidly mounted on the hand. It looks
  from 30 cm, 40 degrees down, at a point 3 cm below the centre between the fingertips, from the
  side across which the fingers close (-x): both fingers and whatever lies between and below them
  fill the image, at about 4 px per cm at 96 px.
- ``hand``: the front view zoomed in on the hand and following it: the front camera's direction
  (azimuth and elevation), looking at the gripper's centre from a third of its distance, so it
  shows what a 32 px crop of the front image around the hand would show, at three times the
  resolution (about 3 px per cm at 96 px), without rendering the whole scene larger. Unlike the
  gripper view it keeps the front view's angle, so the hand, the object and the goal stand to
  each other as they do in the front image, only larger.

The gripper view was chosen over a second fixed view by looking at renders of MT10 tasks: a side
view makes height visible, but at the front view's ~1 px per cm, and from above the arm hides
the objects it reaches for. A sim-to-real gap moves every camera alike (`SimGap.camera`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gymnast.config import CAMERAS, CameraPose, EnvConfig
from gymnast.envs.gap import SimGap

GRIPPER_CAMERA = CameraPose(lookat=(0.0, 0.0, -0.03), distance=0.3, azimuth=0.0, elevation=-40.0)
"""The gripper view, its `lookat` relative to the gripper's centre (Meta-World's ``tcp_center``)."""
HAND_ZOOM = 3.0
"""How much closer than the front camera the hand view looks at the hand (its magnification)."""


def camera_pose(name: str, config: EnvConfig, gap: SimGap, gripper: np.ndarray) -> CameraPose:
    """Where view `name` is while the gripper's centre is at `gripper` (xyz, metres).

    Raises:
        ValueError: `name` is not one of `gymnast.config.CAMERAS`.
    """
    if name == "front":
        return gap.camera(config.camera)
    if name == "gripper":
        lookat = tuple(float(offset + at) for offset, at in zip(GRIPPER_CAMERA.lookat, gripper, strict=True))
        return gap.camera(dataclasses.replace(GRIPPER_CAMERA, lookat=lookat))
    if name == "hand":
        hand = tuple(float(at) for at in gripper)
        return gap.camera(dataclasses.replace(config.camera, lookat=hand, distance=config.camera.distance / HAND_ZOOM))
    raise ValueError(f"unknown camera {name!r}; cameras: {', '.join(CAMERAS)}")
