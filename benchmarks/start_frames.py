"""What an RL run's start states cost to read: every first frame of a dataset's episodes, decoded
alone (`EpisodeDataset.first_frame`, what `gymnast.rl.rollout.dataset_starts` reads) against
decoding each episode whole and keeping its first frame (`load(i).observed_frames[0]`, what it read
before), in the same run on the same episodes; the frames must be identical.

    .venv/bin/python benchmarks/start_frames.py --data runs/headline_cams/data --cameras front,gripper
    # -> benchmarks/results/start_frames.json
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from gymnast.data.lerobot import EpisodeDataset
from gymnast.utils.atomic import write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="a dataset directory")
    parser.add_argument("--cameras", default=None, help="cameras read together, comma-separated (default: the first)")
    parser.add_argument("--episodes", type=int, default=100, help="episodes read (the first ones)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "start_frames.json")
    args = parser.parse_args()
    dataset = EpisodeDataset(args.data, cameras=args.cameras.split(",") if args.cameras else None)
    episodes = range(min(args.episodes, len(dataset)))
    began = time.perf_counter()
    alone = [dataset.first_frame(i) for i in episodes]
    alone_s = time.perf_counter() - began
    began = time.perf_counter()
    whole = [dataset.load(i).observed_frames[0] for i in episodes]
    whole_s = time.perf_counter() - began
    if not all(np.array_equal(a, b) for a, b in zip(alone, whole, strict=True)):
        raise SystemExit("a first frame decoded alone differs from the whole episode's")
    figures = {"data": str(args.data), "cameras": list(dataset.cameras), "episodes": len(episodes),
               "mean_episode_steps": float(np.mean([dataset.lengths[i] for i in episodes])),
               "first_frame_alone_s": alone_s, "whole_episode_s": whole_s, "speedup": whole_s / alone_s}
    print(figures)
    write_json(args.out, figures)


if __name__ == "__main__":
    main()
