"""A tiny real dataset for policy tests: scripted experts on two tasks at 32 px."""

from pathlib import Path

import pytest

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("demos")
    config = CollectConfig(tasks="reach-v3,drawer-close-v3", episodes_per_task=2, noise=(0.0,), failure_fraction=0.5,
                           workers=1, env=EnvConfig(image_size=32, horizon=100))
    collect(config, out, progress=False)
    return out
