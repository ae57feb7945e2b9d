"""What a run saved in ``RUN/config.json``, read back as the settings objects it ran with.

`dataclasses.asdict` and JSON turn a frozen settings dataclass into plain dictionaries, lists and
strings; `from_json` reverses that by the field types, so a nested config (an experiment holding
each stage's settings) needs no hand-written loader. Light on purpose (no torch): the command line
reads these before it knows whether a model will be built.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from gymnast.utils.atomic import read_json

T = TypeVar("T")


def saved_settings(run: Path, section: str | None = None) -> dict:
    """Section `section` of ``RUN/config.json`` (all of it without one): the settings a run was
    started with, for ``--resume``.

    Raises:
        FileNotFoundError: `run` holds no config.json.
    """
    path = Path(run) / "config.json"
    if not path.exists():
        raise FileNotFoundError(f"nothing to resume: {path} does not exist")
    saved = read_json(path)
    return saved if section is None else saved[section]


def from_json(cls: type[T], data: Mapping[str, Any]) -> T:
    """`cls` (a dataclass) from its JSON form: sub-dictionaries become the nested dataclasses, lists
    tuples and strings paths where the field types say so; missing fields keep their defaults.

    A dataclass whose fields were renamed reads its older files through a static method
    ``upgrade_saved(data) -> data`` that gives the saved fields today's names.

    Raises:
        ValueError: `data` has a field that `cls` does not know (saved by another version).
    """
    data = cls.upgrade_saved(data) if hasattr(cls, "upgrade_saved") else data
    hints = typing.get_type_hints(cls)
    unknown = set(data) - {field.name for field in dataclasses.fields(cls)}
    if unknown:
        raise ValueError(f"{cls.__name__} has no field {sorted(unknown)[0]!r} (saved by another version?)")
    return cls(**{name: _value(hints[name], value) for name, value in data.items()})


def _value(hint: Any, value: Any) -> Any:
    """`value` (JSON) as type `hint` says."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if value is None:
        return None
    if origin in (typing.Union, types.UnionType):  # X | None: the one type that is not None
        return _value(next(arg for arg in args if arg is not type(None)), value)
    if dataclasses.is_dataclass(hint):
        return from_json(hint, value)
    if origin is tuple:
        items = (args[0],) * len(value) if len(args) == 2 and args[1] is Ellipsis else args or (Any,) * len(value)
        return tuple(_value(item, element) for item, element in zip(items, value, strict=True))
    if hint is Path:
        return Path(value)
    return value
