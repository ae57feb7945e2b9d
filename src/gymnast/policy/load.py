"""Load a policy checkpoint of any family: the saved spec names the class that rebuilds it.

A small name -> "module:Class" table, imported lazily, so that loading one family never imports
the others. A user's own policy (``python:MODULE:FACTORY[@ARG]`` or ``plugin:NAME[@ARG]``,
`gymnast.utils.plugins`) is one more family: a run that trained it saves the factory it came
from, which rebuilds it before the run's weights are loaded into it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from torch import nn

from gymnast.config import EnvConfig
from gymnast.policy.observation import PolicyArchitecture, simulator_cameras
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import resolve_checkpoint
from gymnast.utils.plugins import import_named, is_plugin, load_plugin, missing_attributes

POLICY_FAMILIES = {
    "vla": "gymnast.policy.vla:EmbeddedVLA",
    "flow_vla": "gymnast.policy.flow_vla:FlowVLA",
    "lerobot": "gymnast.policy.lerobot_load:LeRobotFamily",
    "plugin": "gymnast.policy.load:PluginFamily",
}
"""The key a family's ``spec()`` saves its architecture under -> the class that rebuilds it."""

LEROBOT = "lerobot:"
"""What marks a ``--policy`` as a LeRobot pretrained_model folder rather than a gymnast run."""

PLUGIN_GROUP = "gymnast.policies"
"""The entry-point group where installed packages register policies (``--policy plugin:NAME``)."""

REQUIRED = ("chunk_size", "action_dim", "config", "sample", "log_prob", "log_prob_and_entropy", "chunk_tokens", "act")
"""What gymnast reads off any policy: the `Policy` protocol's members and a ``config`` with the
``image_size`` it sees (and its ``cameras``, for one of several)."""


def is_lerobot(policy: str | Path) -> bool:
    """Whether a ``--policy`` value names a LeRobot folder (``lerobot:PATH``)."""
    return str(policy).startswith(LEROBOT)


def load_policy(run: str | Path) -> nn.Module:
    """The newest checkpoint of a run directory (or a checkpoint directory itself), in eval mode;
    for ``lerobot:PATH``, the LeRobot policy in that pretrained_model folder
    (`gymnast.policy.lerobot_load`); for ``python:MODULE:FACTORY[@ARG]`` or ``plugin:NAME[@ARG]``,
    the user's own policy that factory returns (``gymnast check-policy`` checks it keeps the contract).

    Raises:
        FileNotFoundError: no checkpoint there (the message names the directory).
        ValueError: the checkpoint's spec names no known policy family, or a user's policy lacks a
            part of the contract.
    """
    from gymnast.utils.checkpoint import load_model

    if is_lerobot(run):  # parsed here, so every command taking --policy accepts it
        from gymnast.policy.lerobot_load import load_lerobot

        return load_lerobot(Path(str(run).removeprefix(LEROBOT)))
    if is_plugin(run):
        return plugin_policy(str(run))
    return load_model(Path(run), build_policy)


def plugin_policy(value: str) -> nn.Module:
    """The policy a ``python:`` or ``plugin:`` factory returns, in eval mode; it remembers `value`
    (``gymnast_source``) so that a run that trains it can save where it came from (`PluginFamily`).

    Raises:
        ValueError: it is not an nn.Module (RL trains its parameters) or lacks a part of the contract.
    """
    policy = load_plugin(value, PLUGIN_GROUP)
    if not isinstance(policy, nn.Module):
        raise ValueError(f"--policy {value}: the factory returned a {type(policy).__name__}; a policy is a "
                         "torch.nn.Module (RL trains its parameters)")
    missing = missing_attributes(policy, REQUIRED)
    if not missing and not hasattr(policy.config, "image_size"):
        missing = ["config.image_size"]
    if missing:
        raise ValueError(f"--policy {value}: the factory returned a {type(policy).__name__}, which lacks "
                         f"{', '.join(missing)} of the Policy contract (gymnast.policy.base.Policy; `gymnast "
                         "check-policy` checks it)")
    policy.gymnast_source = value
    return policy.eval()


def policy_spec(policy: Any) -> dict:
    """What a checkpoint of `policy` saves to rebuild it: its family's ``spec()``, or for a user's
    own policy the factory it came from (and its own ``spec()``, if it has one, for the record)."""
    source = getattr(policy, "gymnast_source", None)
    if source is None:
        return policy.spec()
    own = policy.spec() if hasattr(policy, "spec") else None
    return {"plugin": {"source": source, "spec": own}}


class PluginFamily:
    """The `POLICY_FAMILIES` entry of a user's own policy: its factory builds it again (the
    checkpoint's weights are loaded into it after)."""

    @staticmethod
    def from_spec(spec: dict) -> nn.Module:
        return plugin_policy(spec["plugin"]["source"])


def build_policy(spec: dict) -> nn.Module:
    """The policy a saved spec describes (weights not loaded)."""
    family = next((name for name in POLICY_FAMILIES if name in spec), None)
    if family is None:
        raise ValueError(f"the saved model spec has keys {sorted(spec)}; a policy's has one of {sorted(POLICY_FAMILIES)}")
    return import_named(POLICY_FAMILIES[family]).from_spec(spec)


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
    if is_plugin(policy):  # a user's own policy says what it sees only once built
        policy = load_policy(policy)
    if not isinstance(policy, (str, Path)):  # a policy object
        config = getattr(policy, "config", None)
        cameras = getattr(config, "env_cameras", None) or env.cameras
        if hasattr(policy, "gymnast_source"):
            cameras = plugin_cameras(config)
        own = isinstance(config, PolicyArchitecture) or hasattr(policy, "gymnast_source")
        size = getattr(config, "image_size", None) if own else None
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
    if "plugin" in spec:  # a user's own policy trained by a run: its factory says
        config = plugin_policy(spec["plugin"]["source"]).config
        return plugin_cameras(config), config.image_size
    family = next((spec[name] for name in POLICY_FAMILIES if name in spec), {})
    names = {field.name for field in dataclasses.fields(PolicyArchitecture)}
    architecture = PolicyArchitecture(**{key: value for key, value in family.items() if key in names})
    return architecture.env_cameras, architecture.image_size


def plugin_cameras(config: Any) -> tuple[str, ...]:
    """The simulator's views a user's own policy acts on: its config's ``env_cameras``, else those
    its ``cameras`` name (`simulator_cameras`; the front view for a config that names none)."""
    return tuple(getattr(config, "env_cameras", None) or simulator_cameras(tuple(getattr(config, "cameras", ()))))
