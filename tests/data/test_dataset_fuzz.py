"""A valid small dataset mutated at random: every mutation is read, or refused with the project's own error.

Each run applies `MUTATIONS` random mutations (meta fields removed, retyped or given wrong values;
parquet columns dropped, renamed, retyped or rows truncated; files truncated, swapped, deleted or
re-encoded) to copies of a v2.1 and a v3.0 dataset, and reads each copy the way training and
`gymnast inspect --check` do. Reading must end in success or a `DatasetError` (whose message the CLI
prints in one line); any other exception is a traceback a user would see, and fails the test.
The seed is fixed in CI; ``GYMNAST_FUZZ_SEED=N`` (and ``GYMNAST_FUZZ_MUTATIONS=M``) runs others by hand.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import traceback
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from robot_datasets import write_robot_dataset

from gymnast.data.check import check_dataset
from gymnast.data.lerobot import DatasetError, EpisodeDataset
from gymnast.utils.video import VideoCodec, decode_video, encode_video

SEED = int(os.environ.get("GYMNAST_FUZZ_SEED", "0"))
MUTATIONS = int(os.environ.get("GYMNAST_FUZZ_MUTATIONS", "200"))
_VALUES = [None, "", "x", 0, -1, 1.5, True, [], [1], {}, {"a": 1}, "{chunk_index}", 10**12]


def _json_paths(value, prefix=()):
    """Every key path of a JSON value (dicts and lists), depth first."""
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = enumerate(value)
    else:
        return []
    paths = []
    for key, child in items:
        paths.append((*prefix, key))
        paths += _json_paths(child, (*prefix, key))
    return paths


def _mutate_json(value, rng: random.Random):
    """A JSON value with one key removed, retyped or given a wrong value."""
    paths = _json_paths(value)
    if not paths:
        return rng.choice(_VALUES)
    path = rng.choice(paths)
    parent = value
    for key in path[:-1]:
        parent = parent[key]
    action = rng.choice(["remove", "retype", "wrong"])
    if action == "remove":
        del parent[path[-1]]
    elif action == "retype" or not isinstance(parent[path[-1]], (int, float, str)):
        parent[path[-1]] = rng.choice(_VALUES)
    elif isinstance(parent[path[-1]], str):
        parent[path[-1]] = parent[path[-1]][: rng.randrange(len(parent[path[-1]]) + 1)] + rng.choice(["", "_x", "{"])
    else:
        parent[path[-1]] = parent[path[-1]] * rng.choice([0, -1, 2, 1000]) + rng.choice([0, 1])
    return value


def _meta(path: Path, rng: random.Random) -> None:
    if path.suffix == ".json":
        path.write_text(json.dumps(_mutate_json(json.loads(path.read_text()), rng)))
        return
    lines = []
    for line in path.read_text().splitlines():
        try:
            lines.append(json.loads(line))
        except json.JSONDecodeError:  # an earlier mutation's line
            continue
    choice = rng.randrange(3)
    if choice == 0 and lines:
        lines.pop(rng.randrange(len(lines)))
    elif choice == 1 and lines:
        i = rng.randrange(len(lines))
        lines[i] = _mutate_json(lines[i], rng)
    text = "".join(json.dumps(line) + "\n" for line in lines)
    path.write_text(text + ("{not json\n" if choice == 2 else ""))


def _parquet(path: Path, rng: random.Random) -> None:
    try:
        table = pq.read_table(path)
    except pa.ArrowException:  # an earlier mutation of this copy broke it already
        path.write_bytes(b"PAR1")
        return
    name = rng.choice(table.column_names)
    choice = rng.randrange(6)
    if choice == 0:
        table = table.drop_columns([name])
    elif choice == 1:
        table = table.rename_columns([n + "_renamed" if n == name else n for n in table.column_names])
    elif choice == 2:
        table = table.slice(0, rng.randrange(table.num_rows + 1))
    elif choice == 3:
        table = table.set_column(table.column_names.index(name), name, pa.array([str(v) for v in table.column(name).to_pylist()]))
    elif choice == 4:
        table = table.set_column(table.column_names.index(name), name, pa.nulls(table.num_rows))
    else:
        path.write_bytes(path.read_bytes()[: rng.randrange(path.stat().st_size)])
        return
    pq.write_table(table, path)


def _video(path: Path, others: list[Path], rng: random.Random) -> None:
    choice = rng.randrange(5)
    if choice in (2, 3):
        try:
            frames = decode_video(path)
        except ValueError:  # an earlier mutation of this copy broke it already
            choice = 0
    if choice == 0:
        path.write_bytes(path.read_bytes()[: rng.randrange(max(1, path.stat().st_size))])
    elif choice == 1 and len(others) > 1:
        other = rng.choice([p for p in others if p != path])
        data, swapped = path.read_bytes(), other.read_bytes()
        path.write_bytes(swapped)
        other.write_bytes(data)
    elif choice == 2:
        keep = frames[: rng.randrange(1, len(frames) + 1)] if rng.random() < 0.5 else np.concatenate([frames, frames])
        codec = rng.choice([VideoCodec(), VideoCodec("mpeg4", "yuv420p", {"qscale": "2"})])
        path.unlink()
        encode_video(path, keep, rng.choice([5, 10, 30]), codec)
    elif choice == 3:
        path.unlink()
        encode_video(path, np.ascontiguousarray(frames[:, : frames.shape[1] // 2]), 10)  # another frame size
    else:
        path.write_bytes(bytes(rng.randrange(256) for _ in range(64)))


def mutate(root: Path, rng: random.Random) -> str:
    """Apply one random mutation to the dataset at `root`; returns what was done."""
    files = sorted(p for p in root.rglob("*") if p.is_file())
    path = rng.choice(files)
    kind = rng.choice(["change", "change", "change", "delete"])
    if kind == "delete":
        path.unlink()
    elif path.suffix in (".json", ".jsonl"):
        _meta(path, rng)
    elif path.suffix == ".parquet":
        _parquet(path, rng)
    elif path.suffix == ".mp4":
        _video(path, [p for p in files if p.suffix == ".mp4"], rng)
    return f"{kind} {path.relative_to(root)}"


def read_everything(root: Path) -> None:
    """What training and the check read: metadata, every episode (rows and frames), columns, ranges, stats."""
    check_dataset(root)
    dataset = EpisodeDataset(root)
    dataset.action_stats
    for i in range(len(dataset)):
        episode = dataset.load(i)
        dataset.columns(i)
        dataset.frames(i, 0, 1)
        dataset.frames(i, max(0, episode.length - 1), episode.length + 1)


@pytest.fixture(scope="module")
def bases(tmp_path_factory) -> list[Path]:
    """A v2.1 and a v3.0 dataset (2 episodes of 4 steps, 16x24 frames) to mutate copies of."""
    root = tmp_path_factory.mktemp("fuzz_bases")
    return [write_robot_dataset(root / version, version=version, episodes=2, steps=4, height=16, width=24)
            for version in ("v2.1", "v3.0")]


def test_every_mutation_is_read_or_refused_with_the_projects_own_error(bases, tmp_path):
    rng = random.Random(SEED)
    outcomes, tracebacks = {"read": 0, "refused": 0}, []
    for n in range(MUTATIONS):
        root = tmp_path / f"m{n:04d}"
        shutil.copytree(bases[n % len(bases)], root)
        done = [mutate(root, rng) for _ in range(rng.choice([1, 1, 2, 3]))]
        try:
            read_everything(root)
            outcomes["read"] += 1
        except DatasetError:
            outcomes["refused"] += 1
        except Exception:  # noqa: BLE001 - anything else would reach the user as a traceback
            tracebacks.append(f"seed {SEED}, mutation {n} ({'; '.join(done)}):\n{traceback.format_exc()}")
        shutil.rmtree(root)
    assert not tracebacks, f"{len(tracebacks)} of {MUTATIONS} mutations ended in a traceback:\n" + "\n".join(tracebacks[:3])
    assert outcomes["read"] and outcomes["refused"]  # the mutations reach both ends
