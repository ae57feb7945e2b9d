"""RUN/metrics.jsonl: one JSON object per logged step, with fixed prefixes (train/, eval/, time/ ...),
forwarded to the run's trackers (`gymnast.utils.trackers`: TensorBoard, W&B) with its videos and plots."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gymnast.utils.atomic import write_bytes
from gymnast.utils.trackers import Tracker, Trackers


class MetricsLog:
    """Appends metrics to ``RUN/metrics.jsonl`` and forwards them, and the run's videos and plots, to
    its trackers.

    Args:
        run: the run directory.
        resume_step: when resuming from a checkpoint at this step, lines logged after it (by the
            interrupted run, past its last checkpoint) are dropped, so the file reads as if the
            run had never stopped. Without it the run starts afresh and an old file is removed.
        tracker: where else the run logs (`gymnast.utils.trackers.open_trackers`); none by default.
    """

    def __init__(self, run: Path, resume_step: int | None = None, tracker: Tracker | None = None) -> None:
        self.tracker = tracker if tracker is not None else Trackers()
        self.path = Path(run) / "metrics.jsonl"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if resume_step is not None and self.path.exists():
            kept = [line for line in self.path.read_text().splitlines() if line and json.loads(line)["step"] <= resume_step]
            write_bytes(self.path, "".join(f"{line}\n" for line in kept).encode())
        elif resume_step is None and self.path.exists():
            self.path.unlink()

    def log(self, step: int, values: dict[str, float]) -> None:
        with self.path.open("a") as file:
            file.write(json.dumps({"step": step, **values}) + "\n")
        self.tracker.log_metrics(step, values)

    def video(self, key: str, step: int, video: Path | np.ndarray, fps: int = 10) -> None:
        """A video the run wrote (an mp4) or its (T, H, W, 3) frames, to the trackers."""
        self.tracker.log_video(key, step, video, fps)

    def image(self, key: str, step: int, image: Path | np.ndarray) -> None:
        """A plot the run wrote (a PNG) or its (H, W, 3) pixels, to the trackers."""
        self.tracker.log_image(key, step, image)

    def close(self) -> None:
        """Flush and release the trackers (metrics.jsonl is written line by line)."""
        self.tracker.close()

    def drop(self, step: int, prefix: str) -> None:
        """Removes the lines of `step` whose every value is named `prefix`... (an evaluation that a
        crash cut short after logging it, about to be run again)."""
        if not self.path.exists():
            return
        lines = [line for line in self.path.read_text().splitlines() if line]

        def dropped(line: str) -> bool:
            values = json.loads(line)
            return values.pop("step") == step and all(key.startswith(prefix) for key in values)

        write_bytes(self.path, "".join(f"{line}\n" for line in lines if not dropped(line)).encode())


def read_metrics(run: Path) -> list[dict]:
    """Every line of ``RUN/metrics.jsonl`` (empty if the run logged nothing yet)."""
    path = Path(run) / "metrics.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines() if line] if path.exists() else []
