"""Atomic file writes: a reader sees the old file or the new one, never a half-written one (and a
directory whole or not at all); and the one reader of the JSON files they write, whose errors name
the file.

Every writer here writes to a hidden temporary file in the target's directory, flushes it to disk
(fsync), renames it over the target (``os.replace`` is atomic on POSIX and Windows) and fsyncs the
directory so the rename itself survives a power loss. Temporary files are named
``.<name>.<random>.tmp``; a crash can leave one behind, and `is_temporary` recognises them so the
owner of a directory can remove them.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

TEMP_SUFFIX = ".tmp"


def is_temporary(path: Path) -> bool:
    """Whether ``path`` is a temporary file left by an interrupted atomic write."""
    return path.name.startswith(".") and path.name.endswith(TEMP_SUFFIX)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` atomically.

    If the body raises, the temporary file is removed and ``path`` is untouched.

    Args:
        path: the final file path; its parent directories are created.

    Yields:
        A path in the same directory (same file system, so the rename is atomic).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TEMP_SUFFIX)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        _fsync(tmp)
        # mkstemp creates the file private (0600); give it the permissions a plain open() would.
        os.chmod(tmp, 0o666 & ~_current_umask())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_directory(path.parent)


@contextlib.contextmanager
def atomic_directory(path: str | Path, replace: bool = False) -> Iterator[Path]:
    """Yield a hidden staging directory to fill; on success it is renamed to ``path``, so a reader
    sees the whole directory or none of it. If the body raises, the staging directory is removed.

    Args:
        path: the final directory; its parent directories are created.
        replace: an existing ``path`` is removed just before the rename (else the rename fails).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}."))
    try:
        yield staging
        if replace and path.exists():
            shutil.rmtree(path)
        os.replace(staging, path)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes(path: str | Path, data: bytes) -> None:
    """Atomically write ``data`` to ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_json(path: str | Path, obj: Any) -> None:
    """Atomically write ``obj`` as indented JSON (NaN and infinity are refused: not valid JSON)."""
    write_bytes(path, (json.dumps(obj, indent=4, allow_nan=False) + "\n").encode())


def read_json(path: str | Path) -> Any:
    """The JSON content of ``path`` (a run's settings, a stage's record, a checkpoint's state).

    Raises:
        FileNotFoundError: there is no such file.
        ValueError: naming the file and the place, where it is not valid JSON (cut short by a copy,
            edited by hand: gymnast's own writes are atomic).
    """
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON ({error.msg} at line {error.lineno}, column {error.colno}); "
                         "it was cut short or edited: restore it from a copy, or remove it to redo what wrote it"
                         ) from None
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not a JSON text file ({error.reason})") from None


def write_parquet(path: str | Path, table: pa.Table) -> None:
    """Atomically write a pyarrow table as a parquet file."""
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def _fsync(path: Path) -> None:
    with open(path, "rb+") as f:
        os.fsync(f.fileno())


def _fsync_directory(directory: Path) -> None:
    # Directories cannot be opened on Windows; there the rename is durable enough.
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
