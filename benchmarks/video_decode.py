"""How fast a dataset's videos decode to RGB frames, the work every stage that reads a dataset does
(SFT, the world model, the judge, the state model, their refits in Dyna and the equal budgets).

Decodes every video of `--data` with `gymnast.utils.video.decode_video` (one swscale converter per
video) and with the per-frame conversion it replaced (`frame.to_ndarray(format="rgb24")`, which
builds a converter for each frame) as the reference, alternating for `--rounds` rounds (medians),
so that a busy machine slows both alike; checks that both give the same frames.

    .venv/bin/python benchmarks/video_decode.py --data runs/demo/data

Prints and writes --out (default benchmarks/results/video_decode.json).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

import av
import numpy as np

from gymnast.utils.atomic import write_json
from gymnast.utils.video import decode_video


def per_frame_conversion(path: Path) -> np.ndarray:
    """The reference: every frame converted by a converter built for it alone."""
    with av.open(str(path)) as container:
        return np.stack([frame.to_ndarray(format="rgb24") for frame in container.decode(container.streams.video[0])])


def timed(decode, videos: list[Path]) -> tuple[float, int, list[np.ndarray]]:
    began = time.perf_counter()
    frames = [decode(video) for video in videos]
    return time.perf_counter() - began, sum(len(f) for f in frames), frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="a dataset in the LeRobot layout")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "video_decode.json")
    args = parser.parse_args()
    videos = sorted((args.data / "videos").rglob("*.mp4"))
    if not videos:
        raise SystemExit(f"{args.data}/videos: no mp4 files")
    seconds: dict[str, list[float]] = {"per_frame_conversion": [], "decode_video": []}
    for _ in range(args.rounds):
        reference_s, frames, reference = timed(per_frame_conversion, videos)
        ours_s, _, ours = timed(decode_video, videos)
        if not all(np.array_equal(a, b) for a, b in zip(reference, ours, strict=True)):
            raise SystemExit("decode_video and the per-frame conversion gave different frames")
        seconds["per_frame_conversion"].append(reference_s)
        seconds["decode_video"].append(ours_s)
    median = {name: statistics.median(s) for name, s in seconds.items()}
    shape = ours[0].shape[1:]
    result = {
        "data": str(args.data), "videos": len(videos), "frames": frames, "frame_shape": list(shape),
        "rounds": args.rounds, "same_frames": True, "machine": platform.processor() or platform.machine(),
        **{f"{name}_ms_per_frame": 1000 * s / frames for name, s in median.items()},
        "speedup": median["per_frame_conversion"] / median["decode_video"],
    }
    for name, s in median.items():
        print(f"{name:>22}: {1000 * s / frames:.3f} ms a frame ({frames} frames of {tuple(shape)}, {len(videos)} videos)")
    print(f"speed-up {result['speedup']:.2f}x, the same frames")
    write_json(args.out, result)


if __name__ == "__main__":
    main()
