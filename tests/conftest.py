"""Shared test set-up."""

# gymnast sets MUJOCO_GL before mujoco's first import; a test module that imports metaworld or
# mujoco directly would otherwise fix the GL backend too early.
import gymnast  # noqa: F401
