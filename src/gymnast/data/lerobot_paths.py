"""File paths from ``info.json``'s templates, as published datasets write them.

LeRobot v2.x names an episode's files with ``{episode_chunk}`` and ``{episode_index}``, v3.0 a
shared file with ``{chunk_index}`` and ``{file_index}``; both name a camera's folder with
``{video_key}``. Published datasets mix them (a v2.1 ``data_path`` with v3.0's ``{chunk_index}``),
leave the template out, or give one that names no episode. `PathTemplate` reads each placeholder of
the other version as its counterpart, falls back to the version's default template, and, when a
file is still not where the template says, finds a v2.x episode's file by its name
(``episode_000012.parquet``) under the dataset; each such choice is recorded as a deviation.
"""

from __future__ import annotations

import functools
import re
import string
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from gymnast.data.deviations import Deviations
from gymnast.data.lerobot_format import DatasetError

V2_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V2_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
_COUNTERPARTS = {"chunk_index": "episode_chunk", "file_index": "episode_index",
                 "episode_chunk": "chunk_index", "episode_index": "file_index"}
_EPISODE_FILE = re.compile(r"episode_(\d+)\.")


@dataclass(frozen=True)
class PathTemplate:
    """One of ``info.json``'s path templates (``data_path``, ``video_path``), checked once.

    Attributes:
        text: the template read (the dataset's, or the version's default where it has none usable).
        field: its field in ``info.json``.
        info_path: ``info.json``, for messages.
        names: the placeholders this version fills (``episode_chunk``, ``episode_index``, ``video_key``
            for v2.x); a placeholder of the other version is read as its counterpart.
    """

    text: str
    field: str
    info_path: Path
    names: tuple[str, ...]

    @classmethod
    def read(cls, info: Mapping, field: str, default: str, names: tuple[str, ...], info_path: Path,
             notes: Deviations) -> PathTemplate:
        """The template of `field`, or `default` where the dataset's is missing or names no file of its own.

        Raises:
            DatasetError: the template is not a string, is malformed or names an unknown placeholder.
        """
        value = info.get(field)
        if value is None:
            notes.add(info_path, field, f"{field!r} is missing", f"the default template {default!r} is used")
            return cls(default, field, info_path, names)
        if not isinstance(value, str):
            raise DatasetError(f"{info_path}: field {field!r} is {value!r}, expected a path template such as {default!r}")
        used = _placeholders(value, field, info_path)
        unknown = [name for name in used if name not in names and _COUNTERPARTS.get(name) not in names]
        if unknown:
            raise DatasetError(f"{info_path}: field {field!r} ({value!r}) names placeholders {unknown} that no LeRobot "
                               f"version fills; set it to {default!r}")
        foreign = [name for name in used if name not in names]
        if foreign:
            notes.add(info_path, field, f"{field!r} names another version's placeholders "
                      + ", ".join(f"{{{name}}}" for name in foreign),
                      "read as " + ", ".join(f"{{{_COUNTERPARTS[name]}}}" for name in foreign))
        if not {"episode_index", "file_index"} & set(used):
            notes.add(info_path, field, f"{field!r} ({value!r}) names no episode or file",
                      f"the default template {default!r} is used")
            return cls(default, field, info_path, names)
        return cls(value, field, info_path, names)

    def format(self, values: Mapping[str, object]) -> str:
        """The path for `values` (of `names`; the other version's placeholders filled by their counterparts).

        Raises:
            DatasetError: a value does not fit its format (e.g. ``{episode_index:06d}`` given a string).
        """
        filled = dict(values) | {other: values[mine] for other, mine in _COUNTERPARTS.items() if mine in values}
        try:
            return self.text.format(**filled)
        except (KeyError, ValueError, IndexError, TypeError) as e:
            raise DatasetError(f"{self.info_path}: field {self.field!r} ({self.text!r}) cannot be filled with "
                               f"{dict(values)}: {e}") from e


def locate_episode_file(root: Path, path: Path, index: int, folder: str, key: str, notes: Deviations) -> Path:
    """`path` if it exists, else the file named for episode `index` (``episode_000012.<ext>``) under
    ``root/folder`` whose path contains `key` (a camera's files), if exactly one is; else `path`, for
    the error that follows to name."""
    if path.is_file():
        return path
    found = _episode_files(root / folder, path.suffix, key).get(index)
    if found is None:
        return path
    notes.add(found.parent, folder, f"files are not where info.json's template puts them (e.g. {path})",
              f"found by their episode number under {root / folder}")
    return found


@functools.lru_cache(maxsize=32)
def _episode_files(folder: Path, suffix: str, key: str) -> dict[int, Path]:
    """Episode number -> its file under `folder` (only numbers named by one file)."""
    found: dict[int, list[Path]] = {}
    if folder.is_dir():
        for path in folder.rglob(f"episode_*{suffix}"):
            match = _EPISODE_FILE.fullmatch(path.name[: -len(suffix)] + ".")
            if match and key in str(path.relative_to(folder)):
                found.setdefault(int(match.group(1)), []).append(path)
    return {index: paths[0] for index, paths in found.items() if len(paths) == 1}


def _placeholders(template: str, field: str, info_path: Path) -> list[str]:
    try:
        return [name for _, name, _, _ in string.Formatter().parse(template) if name is not None]
    except ValueError as e:
        raise DatasetError(f"{info_path}: field {field!r} ({template!r}) is not a valid path template: {e}") from e
