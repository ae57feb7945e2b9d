"""Judge cost: scoring a batch of RL-length videos with the per-frame judge and the video judge.

    .venv/bin/python benchmarks/judge.py [--videos 64] [--frames 151] [--repeats 3]
    .venv/bin/python benchmarks/judge.py --cameras front,gripper,hand --image-sizes 96 128 \\
        --videos 16 --out benchmarks/results/judge_three_resolution.json

The per-frame judge looks at every frame of a video (a success at any step counts), the video
judge at four; both are timed on the same random videos in the same run (medians after two warm-up calls) (the scores do not
depend on the content's meaning, only its size). Untrained weights at the committed judges'
sizes. With several cameras or image sizes, the per-frame judge is timed at each size in turn
(the video judge sees one camera). Prints and writes the results (default
benchmarks/results/judge.json).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import torch

from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.video import LearnedJudge
from gymnast.utils.atomic import write_json
from policy import seconds_per_call  # benchmarks/policy.py: median wall time after warm-up calls

RESULTS = Path(__file__).parent / "results" / "judge.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=int, default=64, help="videos per call (an RL step's rollouts)")
    parser.add_argument("--frames", type=int, default=151, help="frames per video (start + 150 actions)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cameras", default="front", help="the views side by side in each frame, comma-separated")
    parser.add_argument("--image-sizes", type=int, nargs="+", default=[96], help="the side of each view, in turn")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    cameras = tuple(args.cameras.split(","))
    texts = ["open the drawer"] * args.videos
    result = {"command": " ".join(["benchmarks/judge.py", *sys.argv[1:]]), "videos": args.videos, "frames": args.frames,
              "cameras": list(cameras)}
    for size in args.image_sizes:
        torch.manual_seed(0)
        videos = torch.randint(0, 256, (args.videos, args.frames, size, len(cameras) * size, 3), dtype=torch.uint8)
        judges = [("frames", FrameJudge(JudgeConfig(image_size=size, cameras=cameras)))]
        if len(cameras) == 1:
            judges.append(("video", LearnedJudge(JudgeConfig(image_size=size))))
        suffix = "" if args.image_sizes == [96] else f"_{size}px"
        for name, judge in judges:
            judge.eval()
            seconds = seconds_per_call(lambda: judge.score(videos, texts), args.repeats)
            result[f"{name}{suffix}_s"] = round(seconds, 3)
            result[f"{name}{suffix}_videos_per_s"] = round(args.videos / seconds, 1)
            result[f"{name}{suffix}_frames_per_s"] = round(args.videos * args.frames / seconds, 1)
        if len(cameras) == 1:
            result[f"frames_over_video_cost{suffix}"] = round(result[f"frames{suffix}_s"] / result[f"video{suffix}_s"], 1)
    result |= {"threads": torch.get_num_threads(), "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()}}
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
