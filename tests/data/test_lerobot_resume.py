"""Durability: a crash at any point loses at most the episodes not yet added, and never half-writes."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from data_helpers import assert_same_numbers, make_episode

from gymnast.data import lerobot_writer
from gymnast.data.lerobot import EpisodeDataset, LeRobotWriter

HELPERS = Path(__file__).parent


def committed_files(root: Path) -> list[str]:
    return sorted(
        p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file() and ".staging" not in p.parts
    )


def test_staged_episodes_survive_a_crash_before_flush(tmp_path):
    episodes = [make_episode(4 + i, seed=i) for i in range(3)]
    writer = LeRobotWriter(tmp_path)
    for episode in episodes:
        writer.add(episode)
    del writer  # the process dies without flushing

    resumed = LeRobotWriter(tmp_path)
    assert resumed.keys() == {e.info.key for e in episodes} and resumed.num_staged == 3
    assert resumed.flush() == 3
    dataset = EpisodeDataset(tmp_path)
    for i, episode in enumerate(episodes):  # in the order they were added
        assert_same_numbers(dataset.load(i), episode)


def test_process_killed_between_data_files_and_info_json_recovers_exactly(tmp_path):
    # A real crash: the child process dies (os._exit, no cleanup) when it is about to write
    # info.json of its second flush; data, video and episode files of that flush are on disk.
    script = textwrap.dedent(
        f"""
        import os, sys
        sys.path.insert(0, {str(HELPERS)!r})
        from data_helpers import make_episode
        from gymnast.data import lerobot_writer
        from gymnast.data.lerobot import LeRobotWriter

        writer = LeRobotWriter({str(tmp_path)!r})
        for seed in (0, 1):
            writer.add(make_episode(5, seed=seed))
        writer.flush()
        for seed in (2, 3):
            writer.add(make_episode(6, seed=seed, instruction="close the drawer"))
        real_write_json = lerobot_writer.write_json
        def die_at_commit(path, obj):
            if str(path).endswith("info.json"):
                os._exit(3)
            real_write_json(path, obj)
        lerobot_writer.write_json = die_at_commit
        writer.flush()
        """
    )
    assert subprocess.run([sys.executable, "-c", script], timeout=60).returncode == 3
    assert "data/chunk-000/file-001.parquet" in committed_files(tmp_path)  # the orphan exists

    dataset = EpisodeDataset(tmp_path)  # the reader sees the last commit
    assert len(dataset) == 2 and [e.seed for e in dataset.episodes] == [0, 1]
    assert dataset.info["total_tasks"] == 1

    writer = LeRobotWriter(tmp_path)  # cleans the orphans, rebuilds tasks and stats, keeps staged
    assert "data/chunk-000/file-001.parquet" not in committed_files(tmp_path)
    assert (writer.num_episodes, writer.num_staged) == (2, 2)
    writer.flush()
    dataset = EpisodeDataset(tmp_path)
    assert [e.seed for e in dataset.episodes] == [0, 1, 2, 3]
    for i in range(4):
        assert_same_numbers(
            dataset.load(i),
            make_episode(5 + i // 2, seed=i, instruction=dataset.episodes[i].instruction),
        )
    stats = json.loads((tmp_path / "meta/stats.json").read_text())
    assert stats["action"]["count"] == [2 * 5 + 2 * 6] and dataset.info["total_tasks"] == 2


def test_failed_flush_can_be_retried_in_the_same_process(tmp_path, monkeypatch):
    writer = LeRobotWriter(tmp_path)
    writer.add(make_episode(5, seed=0))
    writer.flush()
    writer.add(make_episode(5, seed=1))

    def disk_full(path, obj):
        if str(path).endswith("info.json"):
            raise OSError("No space left on device")
        real_write_json(path, obj)

    real_write_json = lerobot_writer.write_json
    monkeypatch.setattr(lerobot_writer, "write_json", disk_full)
    with pytest.raises(OSError, match="No space"):
        writer.flush()
    assert len(EpisodeDataset(tmp_path)) == 1
    monkeypatch.setattr(lerobot_writer, "write_json", real_write_json)
    assert writer.flush() == 1
    stats = json.loads((tmp_path / "meta/stats.json").read_text())
    assert stats["action"]["count"] == [10]  # the failed attempt is not counted
    assert [e.seed for e in EpisodeDataset(tmp_path).episodes] == [0, 1]


def test_crash_after_commit_drops_staged_duplicates(tmp_path):
    writer = LeRobotWriter(tmp_path)
    writer.add(make_episode(5, seed=0))
    staged = tmp_path / ".staging" / "00000000.npz"
    shutil.copy(staged, tmp_path / "saved.npz")
    writer.flush()
    shutil.move(tmp_path / "saved.npz", staged)  # as if the crash came before the staged file was deleted

    resumed = LeRobotWriter(tmp_path)
    assert (resumed.num_episodes, resumed.num_staged) == (1, 0)
    assert not staged.exists()
    assert resumed.flush() == 0 and len(EpisodeDataset(tmp_path)) == 1


def test_crash_during_the_first_flush_leaves_no_dataset_and_loses_nothing(tmp_path, monkeypatch):
    writer = LeRobotWriter(tmp_path)
    writer.add(make_episode(5, seed=0))

    def crash(path, obj):
        raise OSError("crash")

    monkeypatch.setattr(lerobot_writer, "write_json", crash)
    with pytest.raises(OSError):
        writer.flush()
    monkeypatch.undo()
    with pytest.raises(FileNotFoundError, match=r"info\.json"):
        EpisodeDataset(tmp_path)

    resumed = LeRobotWriter(tmp_path)
    assert committed_files(tmp_path) == [] and resumed.num_staged == 1
    resumed.flush()
    assert [e.seed for e in EpisodeDataset(tmp_path).episodes] == [0]


def test_leftover_temporary_files_are_removed(tmp_path):
    with LeRobotWriter(tmp_path) as writer:
        writer.add(make_episode(5, seed=0))
    leftover = tmp_path / "data/chunk-000/.file-001.parquet.abc123.tmp"
    leftover.write_bytes(b"half a file")
    LeRobotWriter(tmp_path)
    assert not leftover.exists()
