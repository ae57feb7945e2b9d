"""Load a policy checkpoint of any family: the saved spec names the class that rebuilds it.

A small name -> "module:Class" table, imported lazily, so that loading one family never imports
the others.
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path

from torch import nn

from gymnast.config import EnvConfig
from gymnast.policy.observation import PolicyArchitecture, simulator_cameras
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import resolve_checkpoint

POLICY_FAMILIES = {
    "vla": "gymnast.policy.vla:EmbeddedVLA",
    "flow_vla": "gymnast.policy.flow_vla:FlowVLA",
    "lerobot": "gymnast.policy.lerobot_load:LeRobotFamily",
}
"""The key a family's ``spec()`` saves its architecture under -> the class that rebuilds it."""

LEROBOT = "lerobot:"
"""What marks a ``--policy`` as a LeRobot pretrained_model folder rather than a gymnast run."""


def is_lerobot(policy: str | Path) -> bool:
    """Whether a ``--policy`` value names a LeRobot folder (``lerobot:PATH``)."""
    return str(policy).startswith(LEROBOT)


def load_policy(run: str | Path) -> nn.Module:
    """The newest checkpoint of a run directory (or a checkpoint directory itself), in eval mode;
    or, for ``lerobot:PATH``, the LeRobot policy in that pretrained_model folder
    (`gymnast.policy.lerobot_load`).

    Raises:
        FileNotFoundError: no checkpoint there (the message names the directory).
        ValueError: the checkpoint's spec names no known policy family.
    """
    from gymnast.utils.checkpoint import load_model

    if is_lerobot(run):  # parsed here, so every command taking --policy accepts it
        from gymnast.policy.lerobot_load import load_lerobot

        return load_lerobot(Path(str(run).removeprefix(LEROBOT)))
    return load_model(Path(run), build_policy)


def build_policy(spec: dict) -> nn.Module:
    """The policy a saved spec describes (weights not loaded)."""
    family = next((name for name in POLICY_FAMILIES if name in spec), None)
    if family is None:
        raise ValueError(f"the saved model spec has keys {sorted(spec)}; a policy's has one of {sorted(POLICY_FAMILIES)}")
    module, name = POLICY_FAMILIES[family].split(":")
    return getattr(importlib.import_module(module), name).from_spec(spec)


def policy_env_config(env: EnvConfig, policy: str | Path | object) -> EnvConfig:
    """`env` rendering the views the policy acts on (`PolicyArchitecture.env_cameras`) at the size
    it was trained on: a policy of several cameras is shown them side by side, and a policy
    trained at another image size than the default is shown that size, both read from its run's
    saved spec without building it; the scripted expert and LeRobot policies (which resize each
    view to their own features' shapes) keep `env`'s size, and an env that renders the policy's
    cameras and more is kept (the actor picks the policy's, `gymnast.eval.actors.PolicyActor.seen`).

    Raises:
        ValueError: `env` names cameras other than the default (front) that lack some of the
            policy's, or an image size other than the default that is not the policy's.
    """
    if not isinstance(policy, (str, Path)):  # a policy object
        config = getattr(policy, "config", None)
        cameras = getattr(config, "env_cameras", None) or env.cameras
        size = getattr(config, "image_size", None) if isinstance(config, PolicyArchitecture) else None
    elif is_lerobot(policy) or Path(policy).is_dir():
        cameras, size = saved_env_view(policy)
    else:  # the scripted expert
        cameras, size = env.cameras, None
    default = EnvConfig()
    if size is not None and size != env.image_size:
        if env.image_size != default.image_size:
            raise ValueError(f"the environment renders {env.image_size}px images, but the policy {policy} was trained "
                             f"on {size}px; leave --env.image-size out to render the policy's own")
        env = dataclasses.replace(env, image_size=size)
    if set(cameras) <= set(env.cameras):
        return env
    if env.cameras != default.cameras:
        raise ValueError(f"the environment renders cameras {','.join(env.cameras)}, but the policy {policy} acts on "
                         f"{','.join(cameras)}; leave --cameras out to render the policy's own")
    return dataclasses.replace(env, cameras=cameras)


def saved_env_view(policy: str | Path) -> tuple[tuple[str, ...], int | None]:
    """The simulator's views a saved policy acts on (its architecture's ``env_cameras``) and the
    image size it was trained on (None for a LeRobot policy, which resizes each view itself), read
    from a run's spec or a LeRobot folder's config.json without building it (a folder without one
    gets the front view here; loading it says what is missing)."""
    from gymnast.policy.lerobot_features import folder_cameras

    if is_lerobot(policy):
        config = Path(str(policy).removeprefix(LEROBOT)) / "config.json"
        return simulator_cameras(folder_cameras(read_json(config)) if config.is_file() else ()), None
    spec = read_json(resolve_checkpoint(Path(policy)) / "config.json").get("model", {})
    if "lerobot" in spec:
        return simulator_cameras(folder_cameras(spec["lerobot"]["files"]["config.json"])), None
    family = next((spec[name] for name in POLICY_FAMILIES if name in spec), {})
    names = {field.name for field in dataclasses.fields(PolicyArchitecture)}
    architecture = PolicyArchitecture(**{key: value for key, value in family.items() if key in names})
    return architecture.env_cameras, architecture.image_size
