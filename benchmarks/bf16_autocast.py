"""Whether bfloat16 autocast pays on this machine's CPU: the policy's image encoder (the default
small CNN), forward and backward on a batch of 64 96x96 images, in float32 and under bfloat16
autocast, taking turns for three rounds (medians compared, so a busy machine slows both alike).

On CPUs that compute bfloat16 natively (AVX512-BF16 or AMX) autocast is faster; on the others
torch emulates it and it is several times slower, which is why gymnast enables it only where
`gymnast.utils.device.bf16_is_native` says so (`gymnast doctor` prints which).

    .venv/bin/python benchmarks/bf16_autocast.py   # -> benchmarks/results/bf16_autocast.json
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

from gymnast.policy.vision import SmallCNN
from gymnast.utils.atomic import write_json
from gymnast.utils.device import bf16_is_native


def seconds_per_step(model: torch.nn.Module, images: torch.Tensor, bf16: bool, repeats: int) -> float:
    """Median seconds of one forward and backward pass."""
    times = []
    for _ in range(repeats + 1):  # the first pass warms the kernels up and is not counted
        start = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            loss = model(images).float().square().mean()
        loss.backward()
        times.append(time.perf_counter() - start)
    return statistics.median(times[1:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3, help="timed passes per setting and round")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "bf16_autocast.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    model, images = SmallCNN(128), torch.rand(64, 3, 96, 96)
    rounds = {"float32": [], "bf16_autocast": []}
    for _ in range(3):
        rounds["float32"].append(seconds_per_step(model, images, False, args.repeats))
        rounds["bf16_autocast"].append(seconds_per_step(model, images, True, args.repeats))
    fp32, bf16 = (statistics.median(rounds[name]) for name in ("float32", "bf16_autocast"))
    result = {
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "bf16_native": bf16_is_native("cpu"),
        "threads": args.threads,
        "float32_s_per_step": round(fp32, 4),
        "bf16_autocast_s_per_step": round(bf16, 4),
        "bf16_speedup": round(fp32 / bf16, 3),
        "rounds": {name: [round(t, 4) for t in times] for name, times in rounds.items()},
    }
    print(result)
    write_json(args.out, result)


if __name__ == "__main__":
    main()
