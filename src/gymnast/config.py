"""Configuration: one frozen dataclass per component, and named presets.

Every field's docstring becomes its ``--help`` text. Derived values are properties, never
mutations, and the resolved configuration is saved with every run and dataset.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import tyro

CommaFloats = Annotated[
    tuple[float, ...],
    tyro.constructors.PrimitiveConstructorSpec(
        nargs=1,
        metavar="X,Y,...",
        instance_from_str=lambda args: tuple(float(x) for x in args[0].split(",") if x.strip()),
        is_instance=lambda value: isinstance(value, tuple),
        str_from_instance=lambda value: [",".join(f"{x:g}" for x in value)],
    ),
]
"""A tuple of floats written on the command line as ``0,0.1,0.3``."""

CAMERAS = ("front", "gripper", "hand")
"""The named views of a scene (posed in `gymnast.envs.cameras`): ``front``, the fixed free camera
`EnvConfig.camera`; ``gripper``, a camera that moves with the gripper and looks at its fingers;
``hand``, the front view zoomed three times on the hand, following it."""

CameraNames = Annotated[
    tuple[str, ...],
    tyro.constructors.PrimitiveConstructorSpec(
        nargs=1,
        metavar="NAME,NAME,...",
        instance_from_str=lambda args: tuple(x.strip() for x in args[0].split(",") if x.strip()),
        is_instance=lambda value: isinstance(value, tuple),
        str_from_instance=lambda value: [",".join(value)],
    ),
    # One flag, --cameras, wherever an EnvConfig is on the command line (`gymnast collect --cameras`).
    tyro.conf.arg(prefix_name=False),
]
"""Camera names written on the command line as ``front,gripper``."""


@dataclass(frozen=True)
class CameraPose:
    """A MuJoCo free camera: it looks at `lookat` from `distance` metres away.

    Attributes:
        lookat: world point at the centre of the image (metres).
        distance: camera distance from `lookat` (metres).
        azimuth: horizontal angle of the viewing direction (degrees).
        elevation: vertical angle of the viewing direction (degrees; negative looks down).
    """

    lookat: tuple[float, float, float] = (0.0, 0.66, 0.08)
    distance: float = 1.05
    azimuth: float = -135.0
    elevation: float = -40.0

    def shifted(self, azimuth: float = 0.0, elevation: float = 0.0, distance_scale: float = 1.0) -> CameraPose:
        """The same camera moved by the given offsets (used by the sim-to-real gap)."""
        return CameraPose(
            lookat=self.lookat,
            distance=self.distance * distance_scale,
            azimuth=self.azimuth + azimuth,
            elevation=self.elevation + elevation,
        )


@dataclass(frozen=True)
class EnvConfig:
    """How the real world (and the software simulator) is observed."""

    image_size: int = 96
    """Side of the square camera image in pixels (every MT10 object and goal spans several
    pixels at 96; see docs/environment.md)."""
    horizon: int = 150
    """Steps before an episode is truncated."""
    terminate_on_success: bool = True
    """End the episode at the first step where the task succeeds."""
    camera: CameraPose = field(default_factory=CameraPose)
    """The fixed free camera that shows the arm, the objects and the goal (the front view)."""
    cameras: CameraNames = ("front",)
    """Views rendered into every observation (front, gripper, hand), comma-separated, the primary first:
    obs["image"] shows them side by side and a dataset records each (see gymnast.envs.metaworld)."""

    def __post_init__(self) -> None:
        if self.image_size < 16:
            raise ValueError(f"EnvConfig.image_size must be at least 16 pixels, got {self.image_size}")
        if self.horizon < 1:
            raise ValueError(f"EnvConfig.horizon must be positive, got {self.horizon}")
        unknown = [name for name in self.cameras if name not in CAMERAS]
        if not self.cameras or unknown or len(set(self.cameras)) < len(self.cameras):
            raise ValueError(f"EnvConfig.cameras must be one or more distinct names of {CAMERAS}, "
                             f"got {','.join(self.cameras) or 'none'}")
