"""Training windows: which starts exist, frame/action alignment, batching and the episode cache."""

from __future__ import annotations

import numpy as np
import pytest
from data_helpers import make_episode

from gymnast.data.lerobot import EpisodeDataset, LeRobotWriter
from gymnast.data.schema import Episode, EpisodeInfo
from gymnast.data.windows import TrainingWindows


def numbered_episode(steps: int, episode: int) -> Episode:
    """Frame t is filled with t, action t is [episode, t, t, t]: alignment can be read off the values."""
    t = np.arange(steps + 1)
    return Episode(
        frames=np.broadcast_to(t[:, None, None, None], (steps + 1, 4, 4, 3)).astype(np.uint8),
        states=np.zeros((steps + 1, 4), np.float32),
        env_states=np.zeros((steps + 1, 0), np.float32),
        actions=np.stack([np.full(steps, episode), t[:-1], t[:-1], t[:-1]], axis=1).astype(np.float32),
        rewards=np.zeros(steps, np.float32),
        successes=np.zeros(steps, bool),
        info=EpisodeInfo("reach-v3", f"episode {episode}", False, "random", 0.0, episode),
    )


class FakeDataset:
    """In-memory episodes that count how often they are decoded."""

    def __init__(self, lengths):
        self.lengths = list(lengths)
        self.loads = []

    def load(self, i):
        self.loads.append(i)
        return numbered_episode(self.lengths[i], i)


def test_every_start_with_enough_frames_is_a_window():
    windows = TrainingWindows(FakeDataset([5, 2, 9, 3]), context=2, future=2)
    # T steps -> T + 1 frames -> T + 2 - C - F starts; episode 1 (3 frames) is too short.
    assert len(windows) == 3 + 0 + 7 + 1
    assert [windows.locate(i) for i in (0, 2, 3, 9, 10)] == [(0, 0), (0, 2), (2, 0), (2, 6), (3, 0)]
    assert windows.locate(-1) == (3, 0)
    with pytest.raises(IndexError, match="window 11 is out of range"):
        windows[11]


@pytest.mark.parametrize(("context", "future"), [(1, 1), (3, 2), (2, 0), (1, 6)])
def test_frames_and_actions_are_aligned(context, future):
    windows = TrainingWindows(FakeDataset([6, 4]), context, future)
    for i in range(len(windows)):
        w = windows[i]
        t = w.start
        assert w.context.shape == (context, 4, 4, 3) and w.future.shape == (future, 4, 4, 3)
        assert w.actions.shape == (context + future - 1, 4) and w.actions.dtype == np.float32
        assert w.context[:, 0, 0, 0].tolist() == list(range(t, t + context))
        assert w.future[:, 0, 0, 0].tolist() == list(range(t + context, t + context + future))
        # action k moves window frame k (episode frame t + k) to frame k + 1
        assert w.actions[:, 1].tolist() == list(range(t, t + context + future - 1))
        assert (w.actions[:, 0] == w.episode_index).all() and w.instruction == f"episode {w.episode_index}"


def test_batch_stacks_windows_in_the_given_order():
    windows = TrainingWindows(FakeDataset([6, 5]), context=3, future=2)  # 3 + 2 windows
    batch = windows.batch([4, 0, 2])
    assert batch.context.shape == (3, 3, 4, 4, 3) and batch.future.shape == (3, 2, 4, 4, 3)
    assert batch.actions.shape == (3, 4, 4)
    assert batch.episode_index.tolist() == [1, 0, 0] and batch.start.tolist() == [1, 0, 2]
    assert batch.instructions == ("episode 1", "episode 0", "episode 0")
    np.testing.assert_array_equal(batch.future[2], windows[2].future)


def test_cache_decodes_each_episode_once_and_evicts_least_recently_used():
    source = FakeDataset([6, 4, 5])
    windows = TrainingWindows(source, context=2, future=1, cache_episodes=2)
    for i in range(len(windows)):
        windows[i]
    assert source.loads == [0, 1, 2]
    assert windows.cache_info() == (len(windows) - 3, 3, 2)
    windows.batch([0, 1])  # episode 0 was evicted by episode 2
    assert source.loads == [0, 1, 2, 0]
    windows.batch([len(windows) - 1])  # episode 2 is still cached
    assert source.loads == [0, 1, 2, 0]


def test_a_subset_of_episodes():
    windows = TrainingWindows(FakeDataset([6, 4, 5]), context=1, future=1, episodes=[2, 0])
    assert len(windows) == 5 + 6
    assert windows.locate(0) == (2, 0) and windows.locate(5) == (0, 0)
    with pytest.raises(IndexError, match=r"episodes \[7\] are out of range"):
        TrainingWindows(FakeDataset([6]), context=1, future=1, episodes=[7])


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="context >= 1"):
        TrainingWindows(FakeDataset([6]), context=0, future=1)
    with pytest.raises(ValueError, match="cache_episodes"):
        TrainingWindows(FakeDataset([6]), context=1, future=1, cache_episodes=0)


def test_windows_over_a_written_dataset_stay_aligned(tmp_path):
    # Frames whose grey level encodes their index survive the codec (error well under one step).
    steps = (9, 14)
    with LeRobotWriter(tmp_path) as writer:
        for seed, n in enumerate(steps):
            levels = (10 + 12 * np.arange(n + 1)).astype(np.uint8)
            frames = np.broadcast_to(levels[:, None, None, None], (n + 1, 16, 16, 3)).copy()
            writer.add(make_episode(n, seed=seed, frames=frames))
    dataset = EpisodeDataset(tmp_path)
    windows = TrainingWindows(dataset, context=3, future=2)
    assert len(windows) == (9 - 3) + (14 - 3)
    for i in range(len(windows)):
        w = windows[i]
        ids = np.round((np.concatenate([w.context, w.future]).mean(axis=(1, 2, 3)) - 10) / 12).astype(int)
        assert ids.tolist() == list(range(w.start, w.start + 5))
        expected = make_episode(steps[w.episode_index], seed=w.episode_index).actions[w.start : w.start + 4]
        np.testing.assert_array_equal(w.actions, expected)
