"""System checks run at set-up: can this machine render MuJoCo scenes without a display?"""

from __future__ import annotations

import os
import subprocess
import sys

_PROBE = """
import mujoco
model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>")
renderer = mujoco.Renderer(model, 16, 16)
data = mujoco.MjData(model)
renderer.update_scene(data)
assert renderer.render().shape == (16, 16, 3)
renderer.close()
"""

INSTALL_HINT = {
    "egl": "apt-get install libegl1 libgl1-mesa-dri   (Debian/Ubuntu; Mesa's EGL software renderer)",
    "osmesa": "apt-get install libosmesa6   (then set MUJOCO_GL=osmesa)",
}


def _probe(backend: str) -> tuple[bool, str]:
    """Renders a one-sphere scene in a fresh interpreter (a failed GL load can abort a process)."""
    env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
    result = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=120)
    last_line = (result.stderr.strip().splitlines() or [""])[-1]
    return result.returncode == 0, last_line


def check_rendering() -> tuple[bool, str]:
    """Returns (ok, message): which headless GL backend works, or what to install."""
    wanted = os.environ.get("MUJOCO_GL", "egl")
    ok, error = _probe(wanted)
    if ok:
        return True, f"rendering: ok (MUJOCO_GL={wanted})"
    for other in ("egl", "osmesa"):
        if other != wanted and _probe(other)[0]:
            return True, f"rendering: MUJOCO_GL={wanted} fails ({error}); use MUJOCO_GL={other}, which works"
    hints = "\n  ".join(INSTALL_HINT.values())
    return False, (
        f"rendering: no headless OpenGL backend works (MUJOCO_GL={wanted}: {error}).\n"
        f"Install one of:\n  {hints}"
    )
