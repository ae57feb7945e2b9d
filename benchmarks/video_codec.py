"""Which video codec keeps Meta-World frames faithful enough for world-model training?

Renders random-action rollouts of Meta-World tasks at several image sizes, encodes each rollout
with every candidate codec through `gymnast.utils.video` (the code path the dataset writer uses),
decodes it and reports the PSNR of decoded against raw frames and the file size.

    MUJOCO_GL=egl python benchmarks/video_codec.py            # writes benchmarks/results/video_codec.json

The requirement is PSNR >= 40 dB on every frame (or lossless); ``docs/dataset_format.md`` records
the result and the choice.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from gymnast.utils.video import DEFAULT_CODEC, VideoCodec, decode_video, encode_video, psnr

CANDIDATES = {
    "h264 yuv420p crf18": VideoCodec("libx264", "yuv420p", {"crf": "18"}),
    "h264 yuv420p qp0": VideoCodec("libx264", "yuv420p", {"qp": "0"}),
    "h264 yuv444p crf10": VideoCodec("libx264", "yuv444p", {"crf": "10"}),
    "h264 yuv444p crf6": VideoCodec("libx264", "yuv444p", {"crf": "6"}),
    "h264 yuv444p crf4": VideoCodec("libx264", "yuv444p", {"crf": "4"}),
    "h264 yuv444p crf2": VideoCodec("libx264", "yuv444p", {"crf": "2"}),
    "h264 yuv444p qp0 (default)": DEFAULT_CODEC,
    "h264rgb qp0 (libx264rgb)": VideoCodec("libx264rgb", "rgb24", {"qp": "0"}),
}
# The camera gymnast's Meta-World environment uses (gymnast.config.CameraPose defaults).
CAMERA = {"lookat": (0.0, 0.66, 0.08), "distance": 1.05, "azimuth": -135.0, "elevation": -40.0}
FPS = 80


def render_rollout(task: str, sizes: list[int], steps: int, seed: int) -> dict[int, np.ndarray]:
    """(steps, S, S, 3) uint8 frames per size S of one random-action rollout."""
    import metaworld
    import mujoco

    env = metaworld.env_dict.ALL_V3_ENVIRONMENTS[task]()
    env._partially_observable, env._freeze_rand_vec, env._set_task_called = False, False, True
    env.reset(seed=seed)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = CAMERA["lookat"]
    camera.distance, camera.azimuth, camera.elevation = (
        CAMERA["distance"],
        CAMERA["azimuth"],
        CAMERA["elevation"],
    )
    renderers = {size: mujoco.Renderer(env.model, size, size) for size in sizes}
    rng = np.random.default_rng(seed)
    frames: dict[int, list[np.ndarray]] = {size: [] for size in sizes}
    for _ in range(steps):
        env.step(rng.uniform(-1, 1, 4))
        for size, renderer in renderers.items():
            renderer.update_scene(env.data, camera=camera)
            frames[size].append(renderer.render().copy())
    for renderer in renderers.values():
        renderer.close()
    return {size: np.stack(f) for size, f in frames.items()}


def measure(frames: np.ndarray, codec: VideoCodec, workdir: Path) -> dict:
    """Encode and decode one clip; PSNR in dB (None = infinite, bit-exact), size and timings."""
    path = workdir / "clip.mp4"
    start = time.perf_counter()
    encode_video(path, frames, FPS, codec, keyframes=[0])
    encoded = time.perf_counter()
    decoded = decode_video(path)
    done = time.perf_counter()
    result = psnr(frames, decoded)
    worst = float(result.per_frame.min())
    return {
        "psnr_min_db": worst if np.isfinite(worst) else None,
        "psnr_mean_db": result.mean if np.isfinite(result.mean) else None,
        "lossless": bool(np.isinf(result.per_frame).all()),
        "bytes_per_frame": path.stat().st_size / len(frames),
        "raw_bytes_per_frame": frames[0].nbytes,
        "encode_ms_per_frame": 1000 * (encoded - start) / len(frames),
        "decode_ms_per_frame": 1000 * (done - encoded) / len(frames),
    }


def summarise(rows: list[dict], sizes: list[int]) -> dict:
    """Per codec: the worst frame over all runs and the mean size per frame at each image size."""
    summary = {}
    for name in CANDIDATES:
        runs = [r for r in rows if r["codec"] == name]
        mins = [r["psnr_min_db"] for r in runs if r["psnr_min_db"] is not None]
        summary[name] = {
            "worst_frame_psnr_db": min(mins) if mins else None,
            "lossless": all(r["lossless"] for r in runs),
            "kib_per_frame": {
                size: float(np.mean([r["bytes_per_frame"] for r in runs if r["size"] == size])) / 1024
                for size in sizes
            },
        }
    return summary


def main() -> None:
    """Render, measure every candidate, print one line per run and write the JSON results."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", nargs="+", default=["drawer-open-v3", "pick-place-v3"])
    parser.add_argument("--sizes", nargs="+", type=int, default=[64, 96, 128])
    parser.add_argument("--steps", type=int, default=150)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "video_codec.json")
    args = parser.parse_args()

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed, task in enumerate(args.tasks):
            for size, frames in render_rollout(task, args.sizes, args.steps, seed).items():
                for name, codec in CANDIDATES.items():
                    row = {"task": task, "size": size, "codec": name, **measure(frames, codec, Path(tmp))}
                    rows.append(row)
                    worst, mean = row["psnr_min_db"] or math.inf, row["psnr_mean_db"] or math.inf
                    print(
                        f"{task:16s} {size:4d}px {name:28s} worst {worst:6.2f} dB  mean {mean:6.2f} dB  "
                        f"{row['bytes_per_frame'] / 1024:6.2f} KiB/frame"
                    )
    command = (
        f"MUJOCO_GL=egl python benchmarks/video_codec.py --tasks {' '.join(args.tasks)} "
        f"--sizes {' '.join(map(str, args.sizes))} --steps {args.steps}"
    )
    result = {
        "command": command,
        "camera": CAMERA,
        "fps": FPS,
        "platform": {
            "python": platform.python_version(),
            "machine": platform.machine(),
            "mujoco_gl": os.environ.get("MUJOCO_GL"),
        },
        "summary": summarise(rows, args.sizes),
        "runs": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
