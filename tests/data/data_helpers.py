"""Helpers for the data tests.

Episodes get smooth rendering-like frames, not noise: codecs are tuned for images, so noise would
measure the wrong thing.
"""

from __future__ import annotations

import numpy as np

from gymnast.data.schema import Episode, EpisodeInfo


def smooth_frames(n: int, size: int = 48, seed: int = 0) -> np.ndarray:
    """(n, size, size, 3) uint8: a shaded background with a moving soft-edged disc, like a render."""
    yy, xx = np.mgrid[0:size, 0:size] / size
    background = np.stack([0.3 + 0.4 * xx, 0.4 + 0.3 * yy, 0.5 + 0.3 * xx * yy], axis=-1)
    frames = []
    for t in range(n):
        cx, cy = 0.5 + 0.3 * np.cos(t / 7 + seed), 0.5 + 0.3 * np.sin(t / 5 + seed)
        disc = np.clip((0.15 - np.hypot(xx - cx, yy - cy)) * size / 1.5, 0, 1)[..., None]  # ~1.5 px edge
        frames.append(background * (1 - disc) + np.array([0.85, 0.2, 0.1]) * disc)
    return (np.stack(frames) * 255).round().astype(np.uint8)


def make_episode(
    steps: int,
    seed: int = 0,
    *,
    size: int = 48,
    task: str = "drawer-open-v3",
    instruction: str = "open the drawer",
    behaviour: str = "expert",
    frames: np.ndarray | None = None,
    state_dim: int = 4,
    env_dim: int = 39,
) -> Episode:
    """An episode of ``steps`` actions with random numeric data and smooth frames."""
    rng = np.random.default_rng(seed)
    return Episode(
        frames=smooth_frames(steps + 1, size, seed) if frames is None else frames,
        states=rng.normal(size=(steps + 1, state_dim)).astype(np.float32),
        env_states=rng.normal(size=(steps + 1, env_dim)).astype(np.float32),
        actions=rng.uniform(-1, 1, (steps, 4)).astype(np.float32),
        rewards=rng.normal(size=steps).astype(np.float32),
        successes=rng.random(steps) > 0.5,
        info=EpisodeInfo(task, instruction, bool(rng.random() > 0.5), behaviour, 0.1 * seed, seed, "real"),
    )


def assert_same_numbers(loaded: Episode, original: Episode) -> None:
    """Every numeric field and the info round-trip exactly."""
    for name in ("states", "env_states", "actions", "rewards", "successes"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(original, name), err_msg=name)
    assert loaded.info == original.info
    assert loaded.frames.shape == original.frames.shape


def three_episodes() -> list[Episode]:
    """Three episodes of different lengths and two instructions."""
    return [
        make_episode(12, seed=0),
        make_episode(20, seed=1, instruction="pull the drawer open"),
        make_episode(7, seed=2),
    ]
