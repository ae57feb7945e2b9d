"""Judge cost: scoring a batch of RL-length videos with the per-frame judge and the video judge.

    .venv/bin/python benchmarks/judge.py [--videos 64] [--frames 151] [--repeats 3]

The per-frame judge looks at every frame of a video (a success at any step counts), the video
judge at four; both are timed on the same random videos in the same run (medians after two warm-up calls) (the scores do not
depend on the content's meaning, only its size). Untrained weights at the committed judges'
sizes. Prints and writes benchmarks/results/judge.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

import torch

from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.video import LearnedJudge
from gymnast.utils.atomic import write_json
from policy import seconds_per_call  # benchmarks/policy.py: median wall time after warm-up calls

RESULTS = Path(__file__).parent / "results" / "judge.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=int, default=64, help="videos per call (an RL step's rollouts)")
    parser.add_argument("--frames", type=int, default=151, help="frames per video (start + 150 actions)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.manual_seed(0)
    videos = torch.randint(0, 256, (args.videos, args.frames, 96, 96, 3), dtype=torch.uint8)
    texts = ["open the drawer"] * args.videos
    result = {"videos": args.videos, "frames": args.frames}
    for name, judge in (("frames", FrameJudge(JudgeConfig())), ("video", LearnedJudge(JudgeConfig()))):
        judge.eval()
        seconds = seconds_per_call(lambda: judge.score(videos, texts), args.repeats)
        result[f"{name}_s"] = round(seconds, 3)
        result[f"{name}_videos_per_s"] = round(args.videos / seconds, 1)
    result["frames_over_video_cost"] = round(result["frames_s"] / result["video_s"], 1)
    result |= {"threads": torch.get_num_threads(), "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()}}
    print(json.dumps(result, indent=2))
    write_json(RESULTS, result)


if __name__ == "__main__":
    main()
