"""The device a command runs its models on, resolved once and passed in (modules store none).

``auto`` is CUDA when torch sees a GPU and the CPU otherwise; asking for CUDA where there is none
is an error that says so, not a silent fall back. Models move to the device; the environments,
datasets and rollout records stay on the host, and batches are copied over as they are used
(non-blocking from the host to a GPU).

bfloat16 autocast, which the configs ask for by default, is used only where the hardware computes
bfloat16 natively (`bf16_autocast`): elsewhere torch emulates it and it is slower than float32.
``GYMNAST_CPU_BF16=off`` in the environment makes a CPU that computes it natively run float32 as
one that emulates it would: the same numbers on every CPU, and a native CPU's measure of what the
float32 path costs (the make-demo time of docs/experiment.md).
"""

from __future__ import annotations

import functools
import os
from contextlib import AbstractContextManager
from typing import Literal

import torch

DeviceName = Literal["auto", "cpu", "cuda"]
DEVICE_NAMES: tuple[str, ...] = ("auto", "cpu", "cuda")
CPU_BF16_VARIABLE = "GYMNAST_CPU_BF16"
"""Environment variable: ``off`` runs float32 on the CPU even where it computes bfloat16 natively."""


def resolve_device(name: str = "auto") -> torch.device:
    """`auto`, `cpu`, `cuda` or `cuda:N` -> the torch device.

    Raises:
        ValueError: an unknown name, or CUDA asked for on a machine where torch sees no GPU.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise ValueError(f"--device {name}: torch {torch.__version__} sees no CUDA GPU here; use --device cpu "
                             "(or auto), or install a CUDA build of torch")
        return torch.device(name)
    raise ValueError(f"unknown device {name!r}; choose one of {', '.join(DEVICE_NAMES)} (or cuda:N)")


def module_device(module: torch.nn.Module) -> torch.device:
    """Where a module's parameters live (the CPU for a module without any)."""
    return next(module.parameters(), torch.zeros(0)).device


def to_device(tensor: torch.Tensor, device: torch.device) -> torch.Tensor:
    """`tensor` on `device`; a copy from the host to a GPU does not block the host."""
    return tensor.to(device, non_blocking=device.type == "cuda")


def cpu_bf16_turned_off() -> bool:
    """Whether ``GYMNAST_CPU_BF16=off`` asks for float32 on the CPU (`CPU_BF16_VARIABLE`).

    Raises:
        ValueError: the variable holds something other than auto or off.
    """
    wanted = os.environ.get(CPU_BF16_VARIABLE, "auto").strip().lower()
    if wanted not in ("auto", "off"):
        raise ValueError(f"{CPU_BF16_VARIABLE}={wanted!r}: use auto (bfloat16 where the CPU computes it natively) "
                         "or off (float32 always)")
    return wanted == "off"


@functools.cache
def bf16_is_native(device_type: str) -> bool:
    """Whether `device_type` ("cpu" or "cuda") computes bfloat16 natively: a CUDA GPU that supports
    it, or an x86 CPU with AVX512-BF16 or AMX. On other CPUs (AVX2 only, as many AMD and laptop
    CPUs are) torch emulates bfloat16 and autocast makes a small CNN about 8x slower than float32
    (benchmarks/bf16_autocast.py), where native support makes it faster."""
    if device_type == "cuda":
        return torch.cuda.is_available() and torch.cuda.is_bf16_supported()
    if device_type == "cpu":
        # Private helpers, present since torch 2.1; a torch without them is treated as emulating.
        probes = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
        return any(getattr(torch.cpu, name, lambda: False)() for name in probes)
    return False


def bf16_used(device_type: str) -> bool:
    """Whether bfloat16 autocast runs on `device_type`: where it is native, unless turned off on the CPU."""
    turned_off = device_type == "cpu" and cpu_bf16_turned_off()  # read first: a mistyped setting is named on every CPU
    return bf16_is_native(device_type) and not turned_off


def bf16_autocast(device: torch.device | str, wanted: bool = True) -> AbstractContextManager:
    """bfloat16 autocast on `device` when `wanted` and the device computes bfloat16 natively
    (`bf16_used`); otherwise a disabled context, so the code inside runs in float32."""
    device_type = torch.device(device).type
    return torch.autocast(device_type, dtype=torch.bfloat16, enabled=wanted and bf16_used(device_type))


def bf16_status() -> str:
    """One line for `gymnast doctor`: whether this machine's CPU (and GPU, if any) runs bf16 natively."""
    def said(device_type: str) -> str:
        if not bf16_is_native(device_type):
            return "emulated, float32 used instead"
        return "native, used" if bf16_used(device_type) else f"native, float32 used instead ({CPU_BF16_VARIABLE}=off)"

    line = f"bf16 autocast: CPU {said('cpu')} ({torch.backends.cpu.get_cpu_capability()})"
    return line + (f"; GPU {said('cuda')}" if torch.cuda.is_available() else "")
