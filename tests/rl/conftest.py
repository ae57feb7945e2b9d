"""What the RL tests share: a tiny dataset at the committed policy's image size."""

from pathlib import Path

import pytest

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect


@pytest.fixture(scope="session")
def rl_dataset(tmp_path_factory) -> Path:
    """Two expert scenes of reach-v3 at 96 px (the committed models' size)."""
    out = tmp_path_factory.mktemp("rl_demos")
    config = CollectConfig(tasks="reach-v3", episodes_per_task=2, noise=(0.0,), failure_fraction=0.0, workers=1,
                           env=EnvConfig(image_size=96, horizon=100))
    collect(config, out, progress=False)
    return out
