"""Flag types that several `gymnast` commands share: presets, RL settings, dataset feature keys."""

from __future__ import annotations

import dataclasses
from typing import Literal

from gymnast.cli.settings import flags_of
from gymnast.data.lerobot_format import FeatureKeys
from gymnast.rl.config import RL_PRESETS, RLConfig

Preset = Literal["debug", "demo", "full"]

GPUPreset = Literal["debug", "demo", "full", "gpu"]
"""The presets of the commands that also have one sized for a GPU (docs/gpu.md)."""

RLFlags = flags_of(RLConfig, RL_PRESETS)

KeyFlags = flags_of(FeatureKeys, {"LeRobot": FeatureKeys()})
"""--action-key and --state-key: which dataset features are the actions and the states."""


def key_overrides(keys: KeyFlags) -> dict[str, str | None]:
    """The feature-key flags as `resolve` overrides of a run's ``keys`` setting (None: not given)."""
    return {f"keys.{name}": value for name, value in dataclasses.asdict(keys).items()}


def feature_keys(keys: KeyFlags) -> FeatureKeys:
    """The feature keys the flags name, LeRobot's where a flag is left out."""
    return FeatureKeys(**{name: value for name, value in dataclasses.asdict(keys).items() if value is not None})
