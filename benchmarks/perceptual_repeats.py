"""The verified reward's perceptual distances on videos with repeated frames against distinct ones.

`PerceptualDistance.against_references` runs the network once per run of equal frames. A world
model of one frame per chunk of 5 actions repeats each imagined frame 5 times; a video of the same
length whose frames all differ costs what every video cost before repeats were skipped. 16 rollouts
of 150 frames against 2 references (groups of 8), 96 px, the pretrained network; the two take turns
for `--rounds` rounds so a busy machine slows both alike.

    .venv/bin/python benchmarks/perceptual_repeats.py [--rounds 2]

Prints and writes benchmarks/results/perceptual_repeats.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import torch

from gymnast.utils.atomic import write_json
from gymnast.world_model.metrics import PerceptualDistance

RESULTS = Path(__file__).parent / "results" / "perceptual_repeats.json"


def videos(count: int, repeat: int, generator: torch.Generator) -> torch.Tensor:
    """(count, 150, 3, 96, 96) videos of 150 / `repeat` distinct frames, each shown `repeat` times."""
    return torch.rand(count, 150 // repeat, 3, 96, 96, generator=generator).repeat_interleave(repeat, dim=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    perceptual, index = PerceptualDistance(pretrained=True), torch.tensor([0] * 8 + [1] * 8)
    seconds: dict[str, list[float]] = {"repeated_5x": [], "distinct": []}
    for _ in range(args.rounds):
        for name, repeat in (("repeated_5x", 5), ("distinct", 1)):
            generator = torch.Generator().manual_seed(0)
            pred, references = videos(16, repeat, generator), videos(2, repeat, generator)
            started = time.perf_counter()
            perceptual.against_references(pred, references, index)
            seconds[name].append(round(time.perf_counter() - started, 2))
    result = {"seconds": seconds, "torch_threads": torch.get_num_threads(),
              "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
              "command": " ".join(["benchmarks/perceptual_repeats.py", *sys.argv[1:]])}
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
