"""torchrun with 2 processes (gloo, CPU) trains the same world model and policy as one process
with the same global batch: the same loss curve and the same weights, within float rounding."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from gymnast.utils.checkpoint import resolve_checkpoint
from gymnast.utils.metrics import read_metrics

HERE = Path(__file__).parent
# One process sums the gradients of both halves of a batch in one pass, two processes each of one
# half, then average them: the same numbers added in another order. AdamW turns such a rounding in
# a gradient that is zero but for rounding (an attention key's bias) into a step of up to the
# learning rate, so weights are compared at 1e-4. Under bf16 autocast the kernels also round each
# half differently: the world model (bf16) is compared more loosely, the policy in float32, whose
# losses agree to rounding (a step's loss would differ by far more were the gradients not averaged).
BF16 = {"losses": dict(rtol=2e-3, atol=2e-4), "weights": dict(rtol=2e-3, atol=2e-4)}
FP32 = {"losses": dict(rtol=1e-6, atol=1e-6), "weights": dict(rtol=1e-4, atol=1e-4)}


def _train(command: list[str], out: Path, processes: int) -> None:
    """`command` (a gymnast subcommand, or a script under tests/utils) in 1 process or under torchrun."""
    target = ["-m", "gymnast.cli", *command, "--out", str(out), "--device", "cpu"] if not command[0].endswith(".py") \
        else [str(HERE / command[0]), *command[1:], str(out)]
    launcher = ["-m", "torch.distributed.run", "--nproc_per_node", str(processes), "--master_port", str(29500 + processes)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, *(launcher if processes > 1 else []), *target],
                          capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-3000:]


def _losses(run: Path) -> list[float]:
    return [row["train/loss"] for row in read_metrics(run) if "train/loss" in row]


@pytest.mark.slow
@pytest.mark.parametrize("command, tolerance", [
    (["train-wm", "--preset", "debug", "--steps", "4", "--data"], BF16),  # through the CLI, as users run it
    (["sft_in_fp32.py"], FP32),
], ids=["train-wm", "sft"])
def test_two_processes_train_what_one_does(command, tolerance, tiny_dataset, tmp_path):
    for processes in (1, 2):
        _train([*command, str(tiny_dataset)], tmp_path / f"p{processes}", processes)
    one, two = _losses(tmp_path / "p1"), _losses(tmp_path / "p2")
    assert len(one) == len(two) >= 2
    torch.testing.assert_close(torch.tensor(two), torch.tensor(one), **tolerance["losses"])
    weights = [load_file(resolve_checkpoint(tmp_path / f"p{n}") / "model.safetensors") for n in (1, 2)]
    assert weights[0].keys() == weights[1].keys()
    for name in weights[0]:
        torch.testing.assert_close(weights[1][name], weights[0][name], **tolerance["weights"], msg=name)
    # One run, written once by rank 0: the same checkpoints as one process's.
    assert sorted(os.listdir(tmp_path / "p2" / "checkpoints")) == sorted(os.listdir(tmp_path / "p1" / "checkpoints"))


def test_a_batch_that_does_not_split_over_the_processes_names_the_field():
    from gymnast.utils.distributed import Parallel

    with pytest.raises(ValueError, match="batch_size 5 does not split evenly over the 2 processes"):
        Parallel(rank=1, world_size=2).share(5)
    assert Parallel(rank=1, world_size=2).share(4) == slice(2, 4)
