"""A run stopped after a checkpoint, made from a finished one, for the tests of exact resumption."""

import json
import shutil
from pathlib import Path

import torch
from safetensors.torch import load_file

from gymnast.utils.metrics import read_metrics


def stop_after(whole: Path, interrupted: Path, step: int, metric_lines: int) -> None:
    """Leaves in `interrupted` what the finished run `whole` had on disk when it stopped right after
    its `step` checkpoint: that checkpoint, and its first `metric_lines` metrics lines (one past the
    checkpoint is what a crash before the next one leaves; resuming must drop it)."""
    name = f"{step:06d}"
    (interrupted / "checkpoints").mkdir(parents=True)
    shutil.copytree(whole / "checkpoints" / name, interrupted / "checkpoints" / name)
    (interrupted / "checkpoints" / "last").write_text(name)
    rows = read_metrics(whole)
    (interrupted / "metrics.jsonl").write_text("".join(json.dumps(row) + "\n" for row in rows[:metric_lines]))


def assert_resumed_as_whole(whole: Path, resumed: Path, final_step: int) -> None:
    """The resumed run ended with the finished run's weights, bit for bit, and logged its metrics
    (the wall-clock ones aside)."""
    name = f"{final_step:06d}"
    expected = load_file(whole / "checkpoints" / name / "model.safetensors")
    got = load_file(resumed / "checkpoints" / name / "model.safetensors")
    for key, tensor in expected.items():
        torch.testing.assert_close(got[key], tensor, rtol=0, atol=0, msg=key)
    untimed = lambda rows: [{k: v for k, v in row.items() if not k.startswith("time/")} for row in rows]  # noqa: E731
    assert untimed(read_metrics(resumed)) == untimed(read_metrics(whole))
