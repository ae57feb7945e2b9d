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

    def _update(self, data: mujoco.MjData, markers: Sequence[Marker]) -> None:
        self._renderer.update_scene(data, camera=self._camera, scene_option=self._option)
        scene = self._renderer.scene
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
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

    def render(self, data: mujoco.MjData, markers: Sequence[Marker] = ()) -> np.ndarray:
        """Returns the (H, W, 3) uint8 RGB image of the current state."""
        self._update(data, markers)
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
