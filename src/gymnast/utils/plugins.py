"""Naming an implementation: gymnast's own by a "module:Class" table, a user's own by a plug-in.

World models and policies each keep a small name -> "module:Class" table of the backends gymnast
ships, imported only when asked for (`import_named`). A user's own implementation, such as an
action-conditioned video model of gigabytes or their own PyTorch policy, enters through the same
door in one of two forms, wherever a ``--wm`` or ``--policy`` is taken:

- ``python:MODULE:FACTORY`` names a callable in any importable module;
- ``plugin:NAME`` names an entry point that an installed package registers in the kind's group
  (``gymnast.world_models`` or ``gymnast.policies``), e.g. in its pyproject.toml::

      [project.entry-points."gymnast.world_models"]
      tiny-video = "tiny_video_wm.gymnast_plugin:load"

Either may end in ``@ARG``, a string handed to the factory (usually where its weights are:
``python:my_wm.plugin:load@/ckpt/model``); without it the factory is called with no argument.
The factory returns the model, ready to be called; gymnast moves an ``nn.Module`` to the run's
device and otherwise leaves placement to it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib import import_module, metadata
from pathlib import Path
from typing import Any

PYTHON = "python:"
"""What marks a factory named by its import path."""
PLUGIN = "plugin:"
"""What marks a factory named by an installed entry point."""
ARGUMENT = "@"
"""What separates the factory from the string it is called with."""


def import_named(path: str) -> Any:
    """The attribute a "module:attribute" string names (dots reach into the attribute), its module imported now.

    Raises:
        ValueError: `path` is not of that form, or the module lacks the attribute (named).
        ImportError: the module cannot be imported (the message names it).
    """
    module_name, colon, attribute = path.partition(":")
    if not colon or not module_name or not attribute:
        raise ValueError(f"{path!r}: expected MODULE:ATTRIBUTE, e.g. my_package.world_model:load")
    module = import_module(module_name)
    found: Any = module
    for part in attribute.split("."):
        if not hasattr(found, part):
            raise ValueError(f"{path!r}: module {module_name} has no attribute {attribute!r}")
        found = getattr(found, part)
    return found


def is_plugin(value: str | Path | None) -> bool:
    """Whether a ``--wm`` or ``--policy`` value names a user's own implementation rather than a run."""
    return value is not None and str(value).startswith((PYTHON, PLUGIN))


@dataclass(frozen=True)
class PluginSpec:
    """A parsed ``python:MODULE:FACTORY[@ARG]`` or ``plugin:NAME[@ARG]``.

    Attributes:
        target: MODULE:FACTORY, or the entry point's NAME.
        entry_point: whether `target` is an entry point's name.
        argument: the string the factory is called with, or None (called with none).
    """

    target: str
    entry_point: bool
    argument: str | None = None

    @classmethod
    def parse(cls, value: str | Path) -> PluginSpec:
        """Raises ValueError, showing both forms, for a value of neither."""
        text = str(value)
        prefix = PYTHON if text.startswith(PYTHON) else PLUGIN if text.startswith(PLUGIN) else None
        target, at, argument = text.removeprefix(prefix or "").partition(ARGUMENT)
        if prefix is None or not target or (prefix == PYTHON and ":" not in target):
            raise ValueError(f"{text!r}: expected python:MODULE:FACTORY or plugin:NAME (an installed entry point), "
                             f"either optionally followed by {ARGUMENT}ARG, the string the factory is called with")
        return cls(target, prefix == PLUGIN, argument if at else None)

    def __str__(self) -> str:
        head = (PLUGIN if self.entry_point else PYTHON) + self.target
        return head if self.argument is None else f"{head}{ARGUMENT}{self.argument}"


def entry_point_names(group: str) -> list[str]:
    """The names installed packages register in an entry-point `group`, sorted."""
    return sorted({point.name for point in metadata.entry_points(group=group)})


def plugin_factory(spec: PluginSpec, group: str) -> Callable[..., Any]:
    """The factory a spec names: imported by its path, or looked up among `group`'s entry points.

    Raises:
        ValueError: no entry point of that name in `group` (the installed ones are listed), or the
            path names something that cannot be called.
    """
    if spec.entry_point:
        points = [point for point in metadata.entry_points(group=group) if point.name == spec.target]
        if not points:
            installed = ", ".join(entry_point_names(group)) or "none"
            raise ValueError(f"plugin:{spec.target}: no installed package registers {spec.target!r} in the entry-point "
                             f"group {group!r} (installed there: {installed}); install the package, or name the "
                             "factory by its path: python:MODULE:FACTORY")
        factory = points[0].load()
    else:
        factory = import_named(spec.target)
    if not callable(factory):
        raise ValueError(f"{spec}: {spec.target} is a {type(factory).__name__}, not a factory to call")
    return factory


def load_plugin(value: str | Path, group: str) -> Any:
    """What the factory that `value` names returns (called with its ``@ARG``, if any).

    Args:
        value: ``python:MODULE:FACTORY[@ARG]`` or ``plugin:NAME[@ARG]``.
        group: the entry-point group ``plugin:`` names are looked up in.
    """
    spec = PluginSpec.parse(value)
    factory = plugin_factory(spec, group)
    return factory() if spec.argument is None else factory(spec.argument)


def missing_attributes(model: Any, names: tuple[str, ...]) -> list[str]:
    """The attributes of `names` that `model` lacks (what a contract needs to read off it)."""
    return [name for name in names if not hasattr(model, name)]


@dataclass(frozen=True)
class Breach:
    """One way a user's world model or policy breaks its contract (`gymnast check-wm`, `check-policy`).

    Attributes:
        rule: a short name of the rule broken (e.g. ``frames_dtype``).
        message: what was seen and what to change.
    """

    rule: str
    message: str

    def __str__(self) -> str:
        return f"[{self.rule}] {self.message}"


def format_breaches(what: str, breaches: list[Breach]) -> str:
    """The report `gymnast check-wm` and `check-policy` print: a line per breach, or that none was found."""
    if not breaches:
        return f"{what}: keeps the contract (no breach found)"
    return "\n".join([f"{what}: {len(breaches)} breach(es) of the contract"] + [f"- {breach}" for breach in breaches])
