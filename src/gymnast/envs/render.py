"""Fast headless rendering of Meta-World scenes from free cameras (posed by `gymnast.envs.cameras`).

Meta-World's own render path is slow on a CPU (about 12 frames/s) and its corner cameras are
upside down. A `mujoco.Renderer` with shadows, reflections and multisampling turned off renders
64-128 px frames at well over 100 frames/s per process with Mesa's software rasteriser, and a free
camera can frame the table so that arm, objects and goal are all in view and upright.
"""

from __future__ import annotations

import atexit
import os
import weakref
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from gymnast.config import CameraPose

# MuJoCo's EGL backend terminates its display at exit; a renderer garbage-collected after that
# fails noisily. Our exit hook is registered after the first context exists (and with it MuJoCo's
# hook), so it runs earlier and closes every live renderer in time.
_LIVE_RENDERERS: weakref.WeakSet = weakref.WeakSet()


def _close_live_renderers() -> None:
    for renderer in list(_LIVE_RENDERERS):
        renderer.close()
    for shared, _ in _SHARED.values():  # left by renderers collected without close()
        shared.close()
    _SHARED.clear()


# One GL context with its uploaded meshes and textures costs ~120 MB, most of an environment's
# memory. Environments of the same scene (task and gap) in one process share it: the scene is
# rebuilt from each caller's own MjData at every frame, and poses come from the data alone.
_SHARED: dict[Hashable, list] = {}  # key -> [mujoco.Renderer, number of SceneRenderers using it]


# Every field of a scene geom, to move one within the scene's array (the bindings copy no structs).
_GEOM_FIELDS = [name for name in dir(mujoco.MjvGeom()) if not name.startswith("_")]
_CULL_MARGIN = 1.02, 0.002  # bounding spheres grown by 2% and 2 mm: a geom at a plane is always kept


def drop_unseen_geoms(scene: mujoco.MjvScene, aspect: float) -> int:
    """Removes from `scene` the model geoms whose bounding sphere lies wholly outside the view
    frustum of its camera; returns how many. Returns 0 and changes nothing for a stereo,
    orthographic or explicitly sized frustum.

    Meta-World's robot is ~67,000 triangles, most of a render's time with Mesa's software
    rasteriser (docs/environment.md), which spends it on a triangle whether it lands in the image or
    not: a camera that sees part of the scene (the gripper view) spends most of its time on geometry
    it does not show. A geom wholly
    outside the frustum draws no pixel and, with shadows and reflections off, lights none, so the
    image is bit for bit the one the whole scene gives (tests/envs/test_render_culling.py); the
    kept geoms keep their order, which decides ties in the depth test. Decorations, markers and
    planes (bounding radius 0) are always kept.
    """
    cameras = scene.camera[0], scene.camera[1]
    first = cameras[0]
    if scene.stereo != mujoco.mjtStereo.mjSTEREO_NONE or first.orthographic or first.frustum_width > 0:
        return 0
    # A mono render looks from the midpoint of the two eyes (mjv_averageCamera).
    eye = (np.asarray(cameras[0].pos) + np.asarray(cameras[1].pos)) / 2
    forward, up = np.asarray(first.forward), np.asarray(first.up)
    right = np.cross(forward, up)
    near = first.frustum_near
    half_width = (first.frustum_top - first.frustum_bottom) / 2 * aspect
    # Side planes through the eye, as (x, y, z) normals in camera coordinates pointing out of the view.
    planes = np.array([(1.0, 0.0, -(first.frustum_center + half_width) / near),
                       (-1.0, 0.0, (first.frustum_center - half_width) / near),
                       (0.0, 1.0, -first.frustum_top / near),
                       (0.0, -1.0, first.frustum_bottom / near)])
    planes /= np.linalg.norm(planes, axis=1, keepdims=True)
    geoms = [scene.geoms[index] for index in range(scene.ngeom)]
    bound = np.array([geom.modelrbound for geom in geoms])
    points = (np.array([geom.pos for geom in geoms]) - eye) @ np.stack([right, up, forward], axis=1)  # camera coordinates
    grow, pad = _CULL_MARGIN
    radius = bound * grow + pad
    outside = (points[:, 2] < near - radius) | (points @ planes.T > radius[:, None]).any(axis=1)
    kept = np.flatnonzero(~(outside & (bound > 0))).tolist()
    for to, index in enumerate(kept):
        if to != index:
            source, target = geoms[index], geoms[to]
            for name in _GEOM_FIELDS:
                value = getattr(source, name)
                if isinstance(value, np.ndarray):
                    getattr(target, name)[...] = value
                else:
                    setattr(target, name, value)
    dropped = scene.ngeom - len(kept)
    scene.ngeom = len(kept)
    return dropped


@dataclass(frozen=True)
class Marker:
    """A sphere drawn into the image only (no physics), e.g. to make an invisible goal visible."""

    position: tuple[float, float, float]
    radius: float = 0.025
    rgba: tuple[float, float, float, float] = (0.1, 0.9, 0.1, 1.0)


class SceneRenderer:
    """Renders RGB frames (and segmentation maps) of one MuJoCo model.

    Args:
        model: the MuJoCo model; its multisampling setting is turned off in place.
        height: image height in pixels.
        width: image width in pixels.
        camera: the free camera pose.
        share: renderers given the same key in one process share one GL context. Only models
            built alike (same XML, same visual edits) may share one: geometry, colours and
            textures are read from the model the context was made for.
    """

    def __init__(self, model: mujoco.MjModel, height: int, width: int, camera: CameraPose,
                 share: Hashable | None = None) -> None:
        # Multisampling must be off before the GL context is created; it costs ~4x on a CPU.
        model.vis.quality.offsamples = 0
        self._share = None if share is None else (share, height, width)
        if self._share in _SHARED:
            entry = _SHARED[self._share]
            entry[1] += 1
            self._renderer = entry[0]
        else:
            self._renderer = self._new_renderer(model, height, width)
            if self._share is not None:
                _SHARED[self._share] = [self._renderer, 1]
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera = camera
        self._option = mujoco.MjvOption()
        # Meta-World marks goals with sites of task-specific colours (and some hidden ones);
        # hiding every site lets markers be drawn the same way in every task.
        self._option.sitegroup[:] = 0
        self.height, self.width = height, width
        self._closed = False
        if not _LIVE_RENDERERS:
            atexit.unregister(_close_live_renderers)
            atexit.register(_close_live_renderers)
        _LIVE_RENDERERS.add(self)

    @staticmethod
    def _new_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
        try:
            return mujoco.Renderer(model, height=height, width=width)
        except mujoco.FatalError as error:
            raise RuntimeError(
                "MuJoCo could not create an offscreen OpenGL context "
                f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}). MUJOCO_GL must be set to egl or "
                "osmesa before mujoco is first imported (importing gymnast first does it), and the "
                "system needs libegl1 + libgl1-mesa-dri (or libosmesa6); `gymnast doctor` checks."
            ) from error

    @property
    def camera(self) -> CameraPose:
        return self._pose

    @camera.setter
    def camera(self, pose: CameraPose) -> None:
        self._pose = pose
        self._camera.lookat[:] = pose.lookat
        self._camera.distance = pose.distance
        self._camera.azimuth = pose.azimuth
        self._camera.elevation = pose.elevation

    def _update(self, data: mujoco.MjData, markers: Sequence[Marker], cull: bool = False) -> None:
        self._renderer.update_scene(data, camera=self._camera, scene_option=self._option)
        scene = self._renderer.scene
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        if cull:
            drop_unseen_geoms(scene, self.width / self.height)
        for index, marker in enumerate(markers):
            if scene.ngeom >= scene.maxgeom:
                raise RuntimeError(f"scene has no room for marker geoms (maxgeom={scene.maxgeom})")
            mujoco.mjv_initGeom(
                scene.geoms[scene.ngeom],
                type=mujoco.mjtGeom.mjGEOM_SPHERE,
                size=np.array([marker.radius, 0.0, 0.0]),
                pos=np.asarray(marker.position, dtype=np.float64),
                mat=np.eye(3).ravel(),
                rgba=np.asarray(marker.rgba, dtype=np.float32),
            )
            # mjv_initGeom leaves the ids unset; segmentation maps markers to (index, UNKNOWN).
            geom = scene.geoms[scene.ngeom]
            geom.segid, geom.objid, geom.objtype = scene.ngeom, index, mujoco.mjtObj.mjOBJ_UNKNOWN
            scene.ngeom += 1

    def render(self, data: mujoco.MjData, markers: Sequence[Marker] = (), cull: bool = True) -> np.ndarray:
        """Returns the (H, W, 3) uint8 RGB image of the current state. `cull`: leave out the geoms
        wholly outside the view first (`drop_unseen_geoms`; the image is the same, only faster)."""
        self._update(data, markers, cull)
        return self._renderer.render().copy()

    def render_segmentation(self, data: mujoco.MjData, markers: Sequence[Marker] = ()) -> np.ndarray:
        """Returns (H, W, 2) int32 (object id, object type) per pixel; -1 for background.

        Markers are scene-only geoms, so their pixels carry type `mjOBJ_UNKNOWN`.
        """
        self._renderer.enable_segmentation_rendering()
        try:
            self._update(data, markers)
            return self._renderer.render().copy()
        finally:
            self._renderer.disable_segmentation_rendering()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._share is not None:
            entry = _SHARED[self._share]
            entry[1] -= 1
            if entry[1] > 0:  # others still render with it
                return
            del _SHARED[self._share]
        self._renderer.close()
