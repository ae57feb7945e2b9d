"""Episodes waiting to be written into a dataset, each safe on disk as soon as it is staged.

One ``<n>.npz`` file per episode (numbered in the order staged, so a resumed writer keeps that
order), written atomically and holding only arrays and JSON strings: loading it never unpickles.
An episode with several camera views also holds their names (``views``, JSON) and each view but
the primary, whose frames are ``frames`` (``view_1``, ``view_2``, ...).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from gymnast.data.schema import Episode, EpisodeInfo
from gymnast.utils.atomic import write_bytes

_ARRAYS = ("frames", "states", "env_states", "actions", "rewards", "successes")


class StagingArea:
    """A directory of staged episodes, indexed by staging number.

    Args:
        directory: where the files live (created on the first `add`).
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._keys: dict[int, str] = {}  # staging number -> EpisodeInfo.key
        for path in sorted(directory.glob("*.npz")):
            self._keys[int(path.stem)] = self.info(int(path.stem)).key

    def __len__(self) -> int:
        return len(self._keys)

    def numbers(self) -> list[int]:
        """Staging numbers in the order the episodes were staged."""
        return sorted(self._keys)

    def keys(self) -> frozenset[str]:
        """`EpisodeInfo.key` of every staged episode."""
        return frozenset(self._keys.values())

    def add(self, episode: Episode) -> None:
        """Write the episode durably (it survives a crash once this returns)."""
        number = max(self._keys, default=-1) + 1
        buffer = io.BytesIO()
        names = list(episode.views)
        views = {f"view_{i}": episode.views[name] for i, name in enumerate(names) if i}
        if names:
            views["views"] = np.array(json.dumps(names))
        np.savez(
            buffer,
            **views,
            frames=episode.frames,
            states=episode.states.astype(np.float32),
            env_states=episode.env_states.astype(np.float32),
            actions=episode.actions.astype(np.float32),
            rewards=episode.rewards.astype(np.float32),
            successes=episode.successes.astype(bool),
            info=np.array(json.dumps(episode.info.to_dict())),
        )
        write_bytes(self._path(number), buffer.getvalue())
        self._keys[number] = episode.info.key

    def info(self, number: int) -> EpisodeInfo:
        """The facts of a staged episode, without reading its frames."""
        with np.load(self._path(number), allow_pickle=False) as staged:
            return EpisodeInfo(**json.loads(str(staged["info"])))

    def load(self, number: int) -> Episode:
        """The staged episode."""
        with np.load(self._path(number), allow_pickle=False) as staged:
            arrays = {name: staged[name] for name in _ARRAYS}
            names = json.loads(str(staged["views"])) if "views" in staged else []
            views = {name: staged[f"view_{i}"] if i else arrays["frames"] for i, name in enumerate(names)}
            return Episode(**arrays, info=EpisodeInfo(**json.loads(str(staged["info"]))), views=views)

    def remove(self, number: int) -> None:
        """Delete a staged episode (once it is committed)."""
        self._path(number).unlink()
        del self._keys[number]

    def _path(self, number: int) -> Path:
        return self.directory / f"{number:08d}.npz"
