"""gymnast: train robot policies with reinforcement learning inside a learned world model."""

import os

# MuJoCo chooses its GL backend when it is first imported, and headless machines have no display
# for its default (GLFW); EGL with Mesa renders offscreen everywhere. Set before any submodule
# imports mujoco; a user's own MUJOCO_GL (e.g. osmesa) wins.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
