"""How one imagined step's frames best come from the GPU to the host, as the imagined env keeps them.

A step of B rollouts of 5 actions is (B, 5, 96, 96, 3) uint8 (566 MB at B = 4096), and the env keeps
every step's frames as the episode's video, so each step needs fresh host memory. Three ways, each
timed over 20 steps whose results are all kept:
- ``pageable``: ``frames.cpu()``, through pageable memory;
- ``fresh_pinned``: a freshly page-locked tensor each step, then one copy into it;
- ``staged``: one page-locked buffer kept between steps, then a parallel copy into ordinary memory
  (what `gymnast.envs.imagined` does).

    .venv/bin/python benchmarks/gpu_host_copy.py    # -> benchmarks/results/gpu_host_copy.json

Needs a CUDA device (page-locked memory is a CUDA feature).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

from gymnast.envs.imagined import HostCopier
from gymnast.utils.atomic import write_json

RESULTS = Path(__file__).parent / "results" / "gpu_host_copy.json"
STEPS = 20


def pageable(frames: torch.Tensor) -> np.ndarray:
    return frames.cpu().numpy()


def fresh_pinned(frames: torch.Tensor) -> np.ndarray:
    host = torch.empty(frames.shape, dtype=frames.dtype, pin_memory=True)
    return host.copy_(frames).numpy()


def seconds_per_step(copy, frames: torch.Tensor) -> float:
    kept = [copy(frames)]  # warm-up: the staged copier allocates its buffer here
    torch.cuda.synchronize()
    started = time.perf_counter()
    for _ in range(STEPS):
        kept.append(copy(frames))
    return (time.perf_counter() - started) / STEPS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1024, 4096])
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    if not torch.cuda.is_available():
        sys.exit("benchmarks/gpu_host_copy.py times copies from a GPU; this machine has none")
    result: dict = {"seconds_per_step": {}}
    for batch in args.batches:
        frames = torch.randint(0, 256, (batch, 5, 96, 96, 3), dtype=torch.uint8, device="cuda")
        for name, copy in (("pageable", pageable), ("fresh_pinned", fresh_pinned), ("staged", HostCopier())):
            result["seconds_per_step"][f"{name}_b{batch}"] = round(seconds_per_step(copy, frames), 4)
    result |= {"steps": STEPS, "device": torch.cuda.get_device_name(), "torch": torch.__version__,
               "command": " ".join(["benchmarks/gpu_host_copy.py", *sys.argv[1:]])}
    print(result)
    write_json(args.out, result)


if __name__ == "__main__":
    main()
