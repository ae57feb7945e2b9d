"""What an RL run's start states cost to read: every first frame of a dataset's episodes, decoded
alone (`EpisodeDataset.first_frame`, what `gymnast.rl.rollout.dataset_starts` reads) against
decoding each episode whole and keeping its first frame (`load(i).observed_frames[0]`, what it read
before); and keyframe starts drawn uniformly (`--keyframes uniform`), decoding only each start's
context frames (`gymnast.data.keyframes.dataset_keyframes`) against making them from whole episodes
(`keyframe_start(load(i), ...)`, what it did before). In the same run on the same episodes; the
starts must be identical.

    .venv/bin/python benchmarks/start_frames.py --data runs/headline_cams/data --cameras front,gripper
    # -> benchmarks/results/start_frames.json
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from gymnast.data.keyframes import KeyframeConfig, dataset_keyframes, keyframe_indices, keyframe_start
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
    alone, alone_s = _timed(lambda: [dataset.first_frame(i) for i in episodes])
    whole, whole_s = _timed(lambda: [dataset.load(i).observed_frames[0] for i in episodes])
    if not all(np.array_equal(a, b) for a, b in zip(alone, whole, strict=True)):
        raise SystemExit("a first frame decoded alone differs from the whole episode's")
    config = KeyframeConfig(sampling="uniform")
    context, context_s = _timed(lambda: dataset_keyframes(dataset, episodes, config, seed=0))
    from_whole, from_whole_s = _timed(lambda: _keyframes_from_whole_episodes(dataset, episodes, config))
    if not all(np.array_equal(a.frames, b.frames) and np.array_equal(a.state, b.state)
               for a, b in zip(context, from_whole, strict=True)):
        raise SystemExit("a keyframe start decoded from its context differs from the whole episode's")
    figures = {"data": str(args.data), "cameras": list(dataset.cameras), "episodes": len(episodes),
               "mean_episode_steps": float(np.mean([dataset.lengths[i] for i in episodes])),
               "first_frame_alone_s": alone_s, "whole_episode_s": whole_s, "speedup": whole_s / alone_s,
               "keyframe_context_alone_s": context_s, "keyframe_whole_episode_s": from_whole_s,
               "keyframe_speedup": from_whole_s / context_s}
    print(figures)
    write_json(args.out, figures)


def _timed(work):
    began = time.perf_counter()
    result = work()
    return result, time.perf_counter() - began


def _keyframes_from_whole_episodes(dataset: EpisodeDataset, episodes, config: KeyframeConfig) -> list:
    """The keyframe starts of `dataset_keyframes(..., seed=0)`, each episode decoded whole."""
    rng, starts = np.random.default_rng(0), []
    for i in episodes:
        episode = dataset.load(i)
        starts += [keyframe_start(episode, t, config) for t in keyframe_indices(episode, config, rng)]
    return starts


if __name__ == "__main__":
    main()
