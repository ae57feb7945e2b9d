"""Keyframes: real start states anywhere in a dataset's episodes, not only at their first frames.

Legend: T actions of an episode, t the keyframe's index (0 = the first frame), C context frames,
L the segment's horizon, S state dimensions, A action dimensions.

The systems whose practice in imagination pays off imagine short segments from real frames in
the middle of trajectories (WoVR restarts from real keyframes; VLA-RFT imagines one chunk from
dataset states): a short segment stays close to the real world, and a keyframe near where the task
is decided puts practice where the policy has something to learn. A keyframe start carries what
every environment needs to start there: the C real frames up to it (the imagined env's context),
the recorded state (a grounded world model's start), the demonstration's next actions (the
verified reward's reference) and the real actions that led to it from the scene's first frame
(its ``prefix``: a simulator restores the keyframe exactly by replaying them, which is how
imagined segments are held against the real world).

Sampling (`KeyframeConfig.sampling`):

- ``first``: the first frame (the behaviour before keyframes existed).
- ``uniform``: any frame of any episode, each equally likely.
- ``near_success``: in a successful episode, one of the L frames before its first success (where
  the task is decided); an episode that never succeeded is sampled uniformly.
- ``failures``: any frame of an episode that failed (for a policy's own rollouts: where it fails).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import Episode, EpisodeColumns
from gymnast.envs.starts import Start

SAMPLINGS = ("first", "uniform", "near_success", "failures")


@dataclass(frozen=True)
class KeyframeConfig:
    """Where imagined segments start, and how long they run."""

    sampling: str = "first"
    """How keyframes are drawn: first, uniform, near_success or failures (see the module docstring)."""
    horizon: int = 40
    """L: actions per segment (one policy chunk to about 40); a keyframe within L actions of its
    episode's end keeps the episode's remaining actions as its (shorter) reference."""
    per_episode: int = 1
    """Keyframes drawn from each episode."""
    context_frames: int = 2
    """C: real frames up to the keyframe given as the start's context."""

    def __post_init__(self) -> None:
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"KeyframeConfig.sampling must be one of {SAMPLINGS}, got {self.sampling!r}")
        for name in ("horizon", "per_episode", "context_frames"):
            if getattr(self, name) < 1:
                raise ValueError(f"KeyframeConfig.{name} must be at least 1, got {getattr(self, name)}")


def keyframe_indices(episode: Episode | EpisodeColumns, config: KeyframeConfig, rng: np.random.Generator) -> list[int]:
    """`config.per_episode` keyframe indices t (0 <= t < T) of `episode` by `config.sampling`;
    none for ``failures`` in an episode that succeeded."""
    steps = len(episode.actions)
    if config.sampling == "first":
        return [0] * config.per_episode
    if config.sampling == "failures" and episode.info.success:
        return []
    low, high = 0, steps
    if config.sampling == "near_success" and episode.successes.any():
        high = int(np.argmax(episode.successes)) + 1  # the step after which the first success shows
        low = max(0, high - config.horizon)
    return sorted(int(t) for t in rng.integers(low, high, size=config.per_episode))


def keyframe_start(episode: Episode, t: int, config: KeyframeConfig) -> Start:
    """The start at frame `t` of `episode`: the C frames up to it, its state, the L actions the episode
    took from there (the reference) and the t actions that led there (the prefix)."""
    return _start_at(episode, t, config, lambda first, stop: episode.observed_frames[first:stop])


def dataset_keyframes(dataset: EpisodeDataset, episodes: Sequence[int], config: KeyframeConfig,
                      seed: int = 0) -> list[Start]:
    """Keyframe starts drawn from the given episodes of `dataset` (reproducibly from `seed`), as
    `keyframe_start` makes them from whole episodes, decoding only each start's context frames."""
    rng = np.random.default_rng(seed)
    starts = []
    for i in episodes:
        columns = dataset.columns(i)
        starts += [_start_at(columns, t, config, lambda first, stop: dataset.frames(i, first, stop))
                   for t in keyframe_indices(columns, config, rng)]
    return starts


def _start_at(episode: Episode | EpisodeColumns, t: int, config: KeyframeConfig,
              read_frames: Callable[[int, int], np.ndarray]) -> Start:
    """The start at keyframe `t` of an episode whose frames [first, stop) `read_frames` gives."""
    if not 0 <= t < len(episode.actions):
        raise ValueError(f"keyframe {t} is outside episode of {len(episode.actions)} actions "
                         f"({episode.info.task}, seed {episode.info.seed})")
    # Frames before the first repeat it (the robot standing still), so every start has C frames.
    indices = np.clip(np.arange(t - config.context_frames + 1, t + 1), 0, None)
    frames = read_frames(int(indices[0]), t + 1)[indices - indices[0]]  # (C, H, V*W, 3)
    return Start(episode.info.task, episode.info.seed, episode.info.instruction, frames,
                 reference_actions=episode.actions[t: t + config.horizon].astype(np.float32),
                 prefix=episode.actions[:t].astype(np.float32),
                 state=np.asarray(episode.full_states[t], np.float32))
