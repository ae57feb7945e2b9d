"""Reading speed of the LeRobot readers on datasets that already worked, against the code before a commit.

The readers now check every data file for deviations and read a video one frame past its rows (to
tell a repeated first frame); this measures that reading stays as fast. Both versions run in the
same run on the same datasets, taking turns: the old one from ``git archive BASE src/gymnast`` in a
subprocess, the new one from this checkout, each opening the dataset, reading every episode
(frames and columns), its first frame and its action statistics. Best of ``--rounds``.

    .venv/bin/python benchmarks/dataset_reading.py --base 0d47d36   # -> benchmarks/results/dataset_reading.json
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATASETS = {
    "v2.1, 8 episodes of 60 steps, 96x96": dict(version="v2.1", episodes=8, steps=60, height=96, width=96),
    "v3.0, 8 episodes of 60 steps, 96x96": dict(version="v3.0", episodes=8, steps=60, height=96, width=96),
    "v2.1, 4 episodes of 40 steps, 120x160, 2 cameras": dict(version="v2.1", episodes=4, steps=40, cameras=("a", "b")),
}
TIMER = """
import json, sys, time, logging
logging.disable(logging.WARNING)
from gymnast.data.lerobot import EpisodeDataset
best = float("inf")
for _ in range({repeats}):
    start = time.perf_counter()
    dataset = EpisodeDataset(sys.argv[1])
    for i in range(len(dataset)):
        dataset.load(i); dataset.columns(i); dataset.first_frame(i)
    dataset.action_stats
    best = min(best, time.perf_counter() - start)
print(json.dumps(best))
"""


def time_reading(source: Path, data: Path, repeats: int) -> float:
    """Seconds to read `data` with the gymnast package under `source` (best of `repeats`, in a fresh process)."""
    result = subprocess.run([sys.executable, "-c", TIMER.format(repeats=repeats), str(data)], check=True,
                            capture_output=True, text=True, env={"PYTHONPATH": str(source), "PATH": ""})
    return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="0d47d36", help="commit whose readers are the reference")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/dataset_reading.json")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    from robot_datasets import write_robot_dataset

    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.base, "src/gymnast"], check=True,
                                 capture_output=True).stdout
        tarfile.open(fileobj=io.BytesIO(archive)).extractall(old, filter="data")
        sources = {"before": old / "src", "now": ROOT / "src"}
        results = {}
        for name, options in DATASETS.items():
            data = write_robot_dataset(Path(tmp) / name.replace(" ", "_").replace(",", ""), **options)
            times = {version: float("inf") for version in sources}
            for _ in range(args.rounds):  # taking turns, so that a busy moment slows both alike
                for version, source in sources.items():
                    times[version] = min(times[version], time_reading(source, data, args.repeats))
            results[name] = times | {"ratio": times["now"] / times["before"]}
            print(f"{name}: before {times['before'] * 1000:.0f} ms, now {times['now'] * 1000:.0f} ms "
                  f"({results[name]['ratio']:.2f}x)", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"base": args.base, "rounds": args.rounds, "repeats": args.repeats,
                                    "datasets": results}, indent=2) + "\n")
    print(f"results: {args.out}")


if __name__ == "__main__":
    main()
