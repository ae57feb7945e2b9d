"""Presets, overrides and ``--resume``: one rule for every `gymnast` command that starts a run.

A new run starts from the named preset and replaces the fields given on the command line; the
inputs it reads (a dataset, a policy) must be given. With ``--resume`` the settings and the inputs
all come from what the run saved in ``RUN/config.json``, so ``gymnast CMD --out RUN --resume``
continues it with nothing else typed. A flag given beside ``--resume`` must agree with the saved
value: a resumed run continues exactly, or not at all.

`flags_of` turns a flat settings dataclass into command-line flags, one per field with its docstring
as the help, so that a command need not list the fields again.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import textwrap
import typing
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Annotated, Any, TypeVar

import tyro

from gymnast.utils.settings import saved_settings

C = TypeVar("C")


WHERE_IT_RUNS = frozenset({"device", "runner", "workers", "tracker"})
"""Settings of where a run computes or logs, not of what it computes: with --resume they may differ
from the saved run's (a run started on a GPU can finish on a CPU) and replace its values, in a
nested setting too (``rl.tracker``)."""


def resolve(
    command: str,
    out: Path,
    resume: bool,
    preset: C,
    overrides: Mapping[str, Any],
    inputs: Mapping[str, Any],
    saved: Callable[[], tuple[C, dict[str, Any]]],
    required: Collection[str] = (),
) -> tuple[C, dict[str, Any]]:
    """The settings and inputs of a run: `preset` with `overrides` for a new one, or what `out` saved.

    Args:
        command: the subcommand, for messages.
        out: the run directory.
        resume: continue the run in `out`: settings and inputs from `saved()`.
        preset: the named preset's settings (a frozen dataclass).
        overrides: field -> value given on the command line (None: not given); a dotted name reaches
            into a nested dataclass (``vla.vision``).
        inputs: what the run reads, name -> value given (None: not given).
        saved: the settings and inputs the run in `out` was started with.
        required: the inputs a new run cannot do without.

    Raises:
        ValueError: a new run misses a required input, or a flag given with --resume disagrees
            with the run's saved value (the message names the flag and both values); flags of
            `WHERE_IT_RUNS` replace the saved values instead.
        FileNotFoundError: --resume, and `out` holds no run.
    """
    overrides = {name: value for name, value in overrides.items() if value is not None}
    given = {name: value for name, value in inputs.items() if value is not None}
    if resume:
        config, have_inputs = saved()
        for name in [name for name in overrides if name.rpartition(".")[2] in WHERE_IT_RUNS]:
            config = _replace(config, name, overrides.pop(name))  # a resumed run may continue on another machine
        for name, value in (overrides | given).items():
            have = _field(config, name) if name in overrides else have_inputs.get(name)
            if not _same(value, have):
                raise ValueError(f"{_flag(name)} {_show(value)} disagrees with the run in {out}, which has {name}="
                                 f"{_show(have)}; --resume continues a run with the settings it saved (leave out "
                                 f"{_flag(name)}, or start a new run in another --out)")
        return config, have_inputs
    missing = [_flag(name) for name in required if name not in given]
    if missing:
        raise ValueError(f"gymnast {command} needs {' and '.join(missing)} (or --resume to continue the run in --out)")
    for name, value in overrides.items():
        preset = _replace(preset, name, value)
    return preset, dict(inputs)


def saved_inputs(run: Path, *names: str) -> dict[str, Path | None]:
    """The input paths a run saved beside its settings (top-level entries of ``RUN/config.json``)."""
    saved = saved_settings(run)
    return {name: Path(saved[name]) if saved.get(name) else None for name in names}


def flags_of(cls: type, presets: Mapping[str, Any]) -> type:
    """A frozen dataclass with one optional flag per field of the flat dataclass `cls`: the field's
    docstring is its help, and a flag left out (None) keeps the preset's value, which the help lists."""
    hints, docs = typing.get_type_hints(cls, include_extras=True), field_docs(cls)  # extras: a field's own parser
    fields = []
    for field in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[field.name]):
            raise TypeError(f"flags_of takes flat dataclasses; {cls.__name__}.{field.name} is a {hints[field.name]}")
        values = {name: getattr(preset, field.name) for name, preset in presets.items()}
        default = (f"(default: {next(iter(values.values()))})" if len(set(values.values())) == 1 else
                   "(default: the preset's: " + ", ".join(f"{name} {value}" for name, value in values.items()) + ")")
        flag = Annotated[hints[field.name] | None, tyro.conf.arg(help=docs.get(field.name), help_behavior_hint=default)]
        fields.append((field.name, tyro.conf.DisallowNone[flag], dataclasses.field(default=None)))
    return dataclasses.make_dataclass(f"{cls.__name__}Flags", fields, frozen=True)


def field_docs(cls: type) -> dict[str, str]:
    """Each field's docstring: the string literal under its line in the class body."""
    body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
    return {node.target.id: " ".join(after.value.value.split()) for node, after in zip(body, body[1:])
            if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)}


def _replace(config: Any, name: str, value: Any) -> Any:
    """`config` with field `name` (dotted for a nested dataclass) set to `value`."""
    head, _, rest = name.partition(".")
    return dataclasses.replace(config, **{head: _replace(getattr(config, head), rest, value) if rest else value})


def _field(config: Any, name: str) -> Any:
    return functools.reduce(getattr, name.split("."), config)


def _flag(name: str) -> str:
    return "--" + name.rpartition(".")[2].replace("_", "-")


def _show(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return " ".join(map(_show, value)) or "(none)"
    return str(value)


def _same(given: Any, saved: Any) -> bool:
    """Whether a flag's value is the saved one (paths compared by where they point)."""
    if isinstance(given, (tuple, list)):
        return isinstance(saved, (tuple, list)) and len(given) == len(saved) and all(map(_same, given, saved))
    if isinstance(given, Path):
        return saved is not None and given.resolve() == Path(saved).resolve()
    return given == saved
