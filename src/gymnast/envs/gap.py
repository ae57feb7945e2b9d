"""The software simulator: the real world with a named, configurable sim-to-real gap.

World-Gymnast compares RL in a learned world model with RL in a hand-built simulator (SIMPLER)
whose look and physics differ from the real robot's. Here the Meta-World scene plays the real
world, and the same scene with altered appearance and dynamics plays that simulator. The levels
are fixed recipes, so "mild" means the same thing in every run; their measured effect (expert
success drop, open-loop divergence of replayed actions) is in docs/sim_gap.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import mujoco
import numpy as np

from gymnast.config import CameraPose


@dataclass(frozen=True)
class SimGap:
    """How the software simulator differs from the real world. Identity values mean no gap.

    Attributes:
        name: label recorded with every episode (``env_variant``).
        colour_shift: added to every non-robot RGB colour along a fixed warm tint (0 = none).
        drop_textures: render textured surfaces (table, floor, walls) as flat colours.
        light_scale: multiplies the brightness of every light.
        camera_azimuth: degrees added to the camera's azimuth.
        camera_elevation: degrees added to the camera's elevation.
        camera_distance_scale: multiplies the camera's distance.
        friction_scale: multiplies sliding friction of every geom.
        object_mass_scale: multiplies the mass of every body that is not part of the robot.
        damping_scale: multiplies the damping of every joint.
        action_scale: multiplies the hand displacement commanded by an action.
        gripper_strength: multiplies the stiffness of the gripper fingers' position servos.
    """

    name: str = "none"
    colour_shift: float = 0.0
    drop_textures: bool = False
    light_scale: float = 1.0
    camera_azimuth: float = 0.0
    camera_elevation: float = 0.0
    camera_distance_scale: float = 1.0
    friction_scale: float = 1.0
    object_mass_scale: float = 1.0
    damping_scale: float = 1.0
    action_scale: float = 1.0
    gripper_strength: float = 1.0

    @property
    def env_variant(self) -> str:
        return "real" if self == GAPS["none"] else f"sim-gap-{self.name}"

    def camera(self, pose: CameraPose) -> CameraPose:
        """The camera pose of the gapped simulator, given the real one."""
        return pose.shifted(self.camera_azimuth, self.camera_elevation, self.camera_distance_scale)

    def replace(self, **changes: object) -> SimGap:
        return dataclasses.replace(self, **changes)


GAPS: dict[str, SimGap] = {
    "none": SimGap(),
    "mild": SimGap(
        name="mild",
        colour_shift=0.06,
        light_scale=0.9,
        camera_azimuth=2.0,
        camera_elevation=1.0,
        camera_distance_scale=1.02,
        friction_scale=0.75,
        object_mass_scale=1.5,
        damping_scale=1.5,
        action_scale=0.9,
        gripper_strength=0.7,
    ),
    "strong": SimGap(
        name="strong",
        colour_shift=0.2,
        drop_textures=True,
        light_scale=0.65,
        camera_azimuth=10.0,
        camera_elevation=6.0,
        camera_distance_scale=1.1,
        friction_scale=0.45,
        object_mass_scale=3.0,
        damping_scale=3.0,
        action_scale=0.75,
        gripper_strength=0.4,
    ),
}

# A fixed tint direction (warmer, less blue) so a colour shift is reproducible, not random.
_TINT = np.array([1.0, 0.3, -0.7], dtype=np.float32)


def get_gap(gap: str | SimGap) -> SimGap:
    """Looks a gap level up by name (``none``, ``mild``, ``strong``) or passes a SimGap through."""
    if isinstance(gap, SimGap):
        return gap
    if gap not in GAPS:
        raise ValueError(f"unknown sim-to-real gap {gap!r}; choose one of {', '.join(GAPS)}")
    return GAPS[gap]


def robot_body_mask(model: mujoco.MjModel) -> np.ndarray:
    """(nbody,) bool: bodies in the Sawyer robot's kinematic tree."""
    hand_root = model.body_rootid[model.body("hand").id]
    return model.body_rootid == hand_root


def apply_gap(model: mujoco.MjModel, gap: SimGap) -> None:
    """Alters a freshly loaded model in place (call once, before the first reset)."""
    robot = robot_body_mask(model)
    # A geom with a material is drawn in its material's colour (tinted below); giving it an own
    # colour would replace the material's texture, not tint it.
    scene_geoms = ~robot[model.geom_bodyid] & (model.geom_matid < 0)
    tint = gap.colour_shift * _TINT
    model.geom_rgba[scene_geoms, :3] = np.clip(model.geom_rgba[scene_geoms, :3] + tint, 0.0, 1.0)
    model.mat_rgba[:, :3] = np.clip(model.mat_rgba[:, :3] + tint, 0.0, 1.0)
    if gap.drop_textures:
        model.mat_texid[:] = -1
    model.light_diffuse[:] *= gap.light_scale
    model.light_ambient[:] *= gap.light_scale
    model.vis.headlight.diffuse[:] *= gap.light_scale
    model.vis.headlight.ambient[:] *= gap.light_scale

    model.geom_friction[:, 0] *= gap.friction_scale
    model.body_mass[~robot] *= gap.object_mass_scale
    model.dof_damping[:] *= gap.damping_scale
    # The fingers are position servos (gain kp, bias -kp * q): scaling both scales their stiffness.
    model.actuator_gainprm[:, 0] *= gap.gripper_strength
    model.actuator_biasprm[:, 1] *= gap.gripper_strength
