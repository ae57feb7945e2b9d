"""Training windows: short clips of episodes for world models and policies.

A window starting at frame t of an episode holds C context frames, F future frames and the
C + F - 1 actions between consecutive frames:

    frames    t ............ t+C-1 | t+C .......... t+C+F-1
              '--- context (C) ---' '--- future (F) ----'
    actions   a_t ........................... a_{t+C+F-2}

Action k of a window moves window frame k to window frame k + 1. Every start t whose frames
t .. t+C+F-1 exist is a window, so an episode of T steps (T + 1 frames) has T + 2 - C - F of them.

Legend: B batch, C context frames, F future frames, H/W image height/width, A action dimensions.
"""

from __future__ import annotations

import bisect
import itertools
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from gymnast.data.schema import Episode


class EpisodeSource(Protocol):
    """What windows are cut from, e.g. `gymnast.data.lerobot.EpisodeDataset`."""

    @property
    def lengths(self) -> Sequence[int]:
        """Number of steps T of each episode."""
        ...

    def load(self, i: int) -> Episode:
        """Decode episode ``i``."""
        ...


@dataclass(frozen=True)
class Window:
    """One training example.

    Attributes:
        context: (C, H, W, 3) uint8 frames the model conditions on.
        actions: (C+F-1, A) float32; action k moves window frame k to frame k + 1.
        future: (F, H, W, 3) uint8 frames the model must predict.
        instruction: the episode's language instruction.
        episode_index: the episode's index in the dataset.
        start: index in the episode of the first context frame.
    """

    context: np.ndarray
    actions: np.ndarray
    future: np.ndarray
    instruction: str
    episode_index: int
    start: int


@dataclass(frozen=True)
class WindowBatch:
    """Windows stacked along a leading batch axis.

    Attributes:
        context: (B, C, H, W, 3) uint8.
        actions: (B, C+F-1, A) float32.
        future: (B, F, H, W, 3) uint8.
        instructions: B instructions.
        episode_index: (B,) int64.
        start: (B,) int64.
    """

    context: np.ndarray
    actions: np.ndarray
    future: np.ndarray
    instructions: tuple[str, ...]
    episode_index: np.ndarray
    start: np.ndarray


class CacheInfo(NamedTuple):
    """Decoded-episode cache counters: hits, misses (= episodes decoded) and current size."""

    hits: int
    misses: int
    size: int


class TrainingWindows:
    """Every window of C context + F future frames in the chosen episodes, indexable 0..len-1.

    Windows are ordered by episode, then start. Decoding is the cost, so decoded episodes stay in
    an LRU cache; reading windows in episode order (or sorting a batch, as `batch` does) keeps
    the hit rate high. Usable as a map-style PyTorch dataset.

    Args:
        dataset: the episodes (anything with ``lengths`` and ``load(i)``).
        context: C >= 1 context frames.
        future: F >= 0 future frames.
        episodes: which episodes to use (default: all), e.g. a train split.
        cache_episodes: how many decoded episodes to keep in memory.
    """

    def __init__(
        self,
        dataset: EpisodeSource,
        context: int,
        future: int,
        episodes: Sequence[int] | None = None,
        cache_episodes: int = 16,
    ) -> None:
        if context < 1 or future < 0:
            raise ValueError(f"need context >= 1 and future >= 0, got context={context}, future={future}")
        if cache_episodes < 1:
            raise ValueError(f"cache_episodes must be >= 1, got {cache_episodes}")
        lengths = list(dataset.lengths)
        self.episodes = list(range(len(lengths))) if episodes is None else [int(e) for e in episodes]
        bad = [e for e in self.episodes if not 0 <= e < len(lengths)]
        if bad:
            raise IndexError(f"episodes {bad[:5]} are out of range: the dataset has {len(lengths)}")
        self.dataset, self.context, self.future = dataset, context, future
        self.cache_episodes = cache_episodes
        counts = [max(0, lengths[e] + 2 - context - future) for e in self.episodes]
        # Window i belongs to self.episodes[k] when offsets[k] <= i < offsets[k + 1].
        self._offsets = [0, *itertools.accumulate(counts)]
        self._cache: OrderedDict[int, Episode] = OrderedDict()
        self._hits = self._misses = 0

    def __len__(self) -> int:
        return self._offsets[-1]

    def locate(self, i: int) -> tuple[int, int]:
        """(episode index, start frame) of window ``i``."""
        if not -len(self) <= i < len(self):
            raise IndexError(f"window {i} is out of range: there are {len(self)}")
        i %= len(self)
        k = bisect.bisect_right(self._offsets, i) - 1
        return self.episodes[k], i - self._offsets[k]

    def __getitem__(self, i: int) -> Window:
        episode_index, start = self.locate(i)
        episode = self._episode(episode_index)
        n_frames = self.context + self.future
        frames = episode.frames[start : start + n_frames]  # (C+F, H, W, 3)
        return Window(
            context=frames[: self.context],
            actions=episode.actions[start : start + n_frames - 1].astype(np.float32),
            future=frames[self.context :],
            instruction=episode.info.instruction,
            episode_index=episode_index,
            start=start,
        )

    def batch(self, indices: Sequence[int]) -> WindowBatch:
        """Stack the windows ``indices`` (in the given order; decoded in episode order)."""
        if len(indices) == 0:
            raise ValueError("batch() needs at least one index")
        order = sorted(range(len(indices)), key=lambda j: self.locate(indices[j]))
        windows: list[Window | None] = [None] * len(indices)
        for j in order:
            windows[j] = self[indices[j]]
        return WindowBatch(
            context=np.stack([w.context for w in windows]),
            actions=np.stack([w.actions for w in windows]),
            future=np.stack([w.future for w in windows]),
            instructions=tuple(w.instruction for w in windows),
            episode_index=np.array([w.episode_index for w in windows], dtype=np.int64),
            start=np.array([w.start for w in windows], dtype=np.int64),
        )

    def cache_info(self) -> CacheInfo:
        """Counters of the decoded-episode cache."""
        return CacheInfo(self._hits, self._misses, len(self._cache))

    def _episode(self, i: int) -> Episode:
        episode = self._cache.pop(i, None)
        if episode is None:
            self._misses += 1
            episode = self.dataset.load(i)
        else:
            self._hits += 1
        self._cache[i] = episode
        if len(self._cache) > self.cache_episodes:
            self._cache.popitem(last=False)
        return episode
