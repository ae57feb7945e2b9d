"""How many pixels each task object and goal marker covers: the check behind the image size.

A policy that sees only pixels cannot act on an object two pixels wide. This renders a
segmentation map of the initial frame and counts the pixels of every movable scene body (the
robot, table, walls and floor excluded) and of the goal marker, so the default resolution can be
chosen, and re-checked, with numbers.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from gymnast.config import EnvConfig
from gymnast.envs.gap import robot_body_mask
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.utils.atomic import write_json
from gymnast.utils.images import contact_sheet, save_png

GOAL_MARKER = "goal marker"
_STATIC_BODIES = {"world", "tablelink", "RetainingWall", "mocap"}


def object_pixel_counts(env: MetaWorldEnv) -> dict[str, int]:
    """Pixels covered by each visible task object and by the goal marker, in the current frame.

    Objects are named by the top-most non-static body of their kinematic tree (e.g. a drawer's
    case and its sliding part together), so a handle counts with the thing it belongs to.
    """
    model = env.mujoco_model
    seg = env.segmentation()
    objid, objtype = seg[..., 0], seg[..., 1]
    robot = robot_body_mask(model)
    counts: dict[str, int] = {}
    geoms, geom_pixels = np.unique(objid[objtype == mujoco.mjtObj.mjOBJ_GEOM], return_counts=True)
    for geom, pixels in zip(geoms, geom_pixels):
        body = _object_root(model, int(model.geom_bodyid[geom]))
        if body is None or robot[body]:
            continue
        name = model.body(body).name or f"body{body}"
        counts[name] = counts.get(name, 0) + int(pixels)
    marker_pixels = int(np.sum(objtype == mujoco.mjtObj.mjOBJ_UNKNOWN))
    if env.markers():
        counts[GOAL_MARKER] = marker_pixels
    return counts


def _object_root(model: mujoco.MjModel, body: int) -> int | None:
    """The highest ancestor of `body` that is not a static scene body (None if it is static)."""
    if model.body(body).name in _STATIC_BODIES:
        return None
    while model.body_parentid[body] != 0 and model.body(int(model.body_parentid[body])).name not in _STATIC_BODIES:
        body = int(model.body_parentid[body])
    return body


def effective_width(pixels: int) -> float:
    """Side of the square with the same area: a size in pixels that does not depend on shape."""
    return float(np.sqrt(pixels))


def write_task_sheet(out: Path, tasks: tuple[str, ...], seed: int, gap: str, config: EnvConfig) -> Path:
    """A PNG of every task's first frame (data seed `seed`, in the world `gap`), and beside it a JSON of
    the pixels each object covers there; returns the PNG's path."""
    frames, labels, sizes = [], [], {}
    for task in tasks:
        world = MetaWorldEnv(task, config, gap=gap)
        obs, _ = world.reset(seed=seed)
        frames.append(obs["image"])
        labels.append(task.removesuffix("-v3"))
        sizes[task] = object_pixel_counts(world)
        world.close()
    save_png(contact_sheet(frames, labels, columns=5, scale=max(1, 192 // config.image_size)), out)
    write_json(out.with_suffix(".json"), {"image_size": config.image_size, "seed": seed, "pixels": sizes})
    return out
