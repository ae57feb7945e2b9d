"""Shared test set-up."""

# gymnast sets MUJOCO_GL before mujoco's first import; a test module that imports metaworld or
# mujoco directly would otherwise fix the GL backend too early.
import gymnast  # noqa: F401

from pathlib import Path

import pytest

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """A tiny real dataset: scripted experts (and failures) on two tasks at 32 px."""
    out = tmp_path_factory.mktemp("demos")
    config = CollectConfig(tasks="reach-v3,drawer-close-v3", episodes_per_task=2, noise=(0.0,), failure_fraction=0.5,
                           workers=1, env=EnvConfig(image_size=32, horizon=100))
    collect(config, out, progress=False)
    return out
