"""What the reader notes about data rows: timestamps are read within each episode of a file."""

from pathlib import Path

import numpy as np
import pyarrow as pa

from gymnast.data.deviations import Deviations, check_rows

FPS = 80.0
FEATURES = {name: {"dtype": "int64"} for name in ("episode_index", "frame_index", "index", "task_index")}
FEATURES["timestamp"] = {"dtype": "float32"}


def rows(stamps: list[float], episodes: list[int]) -> pa.Table:
    frames = [i - episodes.index(e) for i, e in enumerate(episodes)]
    return pa.table({"timestamp": pa.array(stamps, pa.float32()), "episode_index": episodes, "frame_index": frames,
                     "index": list(range(len(stamps))), "task_index": [0] * len(stamps)})


def timestamp_notes(table: pa.Table) -> list[str]:
    notes = Deviations()
    check_rows(table, Path("data/chunk-000/file-000.parquet"), FPS, FEATURES, notes)
    return [d.found for d in notes if d.field == "timestamp"]


def test_a_file_of_several_episodes_restarts_its_timestamps_at_each_one_without_a_note():
    stamps = list(np.arange(5) / FPS) + list(np.arange(3) / FPS)
    assert timestamp_notes(rows(stamps, [0] * 5 + [1] * 3)) == []


def test_timestamps_off_the_frame_rate_inside_an_episode_are_noted():
    stamps = list(np.arange(5) / (2 * FPS)) + list(np.arange(3) / FPS)
    assert timestamp_notes(rows(stamps, [0] * 5 + [1] * 3)) == ["timestamps step by 0.00625 s, not 1/fps = 0.0125 s"]
