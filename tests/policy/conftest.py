"""What the LeRobot adapter's tests share: tiny LeRobot policies, written once per session.

LeRobot is part of `make test`'s install; if it is missing, the fixtures fail with the install
command (`gymnast.policy.lerobot_import.require_lerobot`) rather than skipping.
"""

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def lerobot_act(tmp_path_factory) -> Path:
    """A randomly initialised ACT (96 px image, 4-d actions, 5 executed of 8 predicted)."""
    from gymnast.policy.lerobot_init import new_act

    return new_act(tmp_path_factory.mktemp("act") / "pretrained_model", chunk=5, predicted=8, action_std=0.5)


@pytest.fixture(scope="session")
def lerobot_smolvla(tmp_path_factory) -> Path:
    """A tiny randomly initialised SmolVLA on a tiny VLM written beside it."""
    from gymnast.policy.lerobot_init import new_smolvla

    return new_smolvla(tmp_path_factory.mktemp("smolvla") / "pretrained_model", chunk=5, predicted=8, action_std=0.5)
