"""A per-user cache of small arrays on disk, shared by every process: for values that cost seconds
to compute and come out the same every time, such as a sentence's embedding, whose encoder takes
about 5 s to import and load in each fresh worker process.

Where: ``$GYMNAST_CACHE_DIR`` if set (empty or ``off`` turns the cache off), else
``$XDG_CACHE_HOME/gymnast``, else ``~/.cache/gymnast``. Each value is one ``.npy`` file named by
the hash of its key and written atomically, so concurrent writers of one key race harmlessly
(they write the same bytes) and a reader never sees half a file. A file that cannot be read or
has the wrong shape counts as missing and is computed again; a cache that cannot be written is
given up for the process with one warning, and the caller computes as if there were none.
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

import numpy as np

from gymnast.utils.atomic import atomic_path

logger = logging.getLogger(__name__)

CACHE_ENV = "GYMNAST_CACHE_DIR"
"""The environment variable that moves the cache (or, empty or ``off``, turns it off)."""


def cache_root() -> Path | None:
    """The cache's directory, or None when `CACHE_ENV` turns it off."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return None if chosen.strip() in ("", "off") else Path(chosen).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "gymnast"


class ArrayCache:
    """Arrays of one kind under ``<cache root>/<namespace>``, looked up by a string key.

    Args:
        namespace: a relative folder; put in it whatever makes a value valid (a model's name and
            version), so that values of another version are never read.
    """

    def __init__(self, namespace: str) -> None:
        root = cache_root()
        self.directory = None if root is None else root / namespace

    def path(self, key: str) -> Path | None:
        if self.directory is None:
            return None
        return self.directory / f"{hashlib.sha256(key.encode()).hexdigest()[:40]}.npy"

    def get(self, key: str, shape: tuple[int, ...]) -> np.ndarray | None:
        """The array stored for `key`, or None if there is none (or it is unreadable, or not `shape`)."""
        path = self.path(key)
        if path is None or not path.is_file():
            return None
        try:
            array = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as error:
            logger.debug("cache file %s unreadable (%s); computing again", path, error)
            return None
        return array if array.shape == shape else None

    def put(self, key: str, array: np.ndarray) -> None:
        """Stores `array` for `key`; if the cache cannot be written, turns itself off with a warning."""
        path = self.path(key)
        if path is None:
            return
        try:
            with atomic_path(path) as tmp, open(tmp, "wb") as file:
                np.save(file, np.ascontiguousarray(array), allow_pickle=False)
        except OSError as error:
            logger.warning("cannot write the cache in %s (%s); going on without it (set %s to move it)",
                           self.directory, error, CACHE_ENV)
            self.directory = None
