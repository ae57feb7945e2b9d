"""The device a command runs its models on, resolved once and passed in (modules store none).

``auto`` is CUDA when torch sees a GPU and the CPU otherwise; asking for CUDA where there is none
is an error that says so, not a silent fall back. Models move to the device; the environments,
datasets and rollout records stay on the host, and batches are copied over as they are used
(non-blocking from the host to a GPU).

bfloat16 autocast, which the configs ask for by default, is used only where the hardware computes
bfloat16 natively (`bf16_autocast`): elsewhere torch emulates it and it is slower than float32.
"""

from __future__ import annotations

import functools
from contextlib import AbstractContextManager
from typing import Literal

import torch

DeviceName = Literal["auto", "cpu", "cuda"]
DEVICE_NAMES: tuple[str, ...] = ("auto", "cpu", "cuda")


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


def bf16_autocast(device: torch.device | str, wanted: bool = True) -> AbstractContextManager:
    """bfloat16 autocast on `device` when `wanted` and the device computes bfloat16 natively
    (`bf16_is_native`); otherwise a disabled context, so the code inside runs in float32."""
    device_type = torch.device(device).type
    return torch.autocast(device_type, dtype=torch.bfloat16, enabled=wanted and bf16_is_native(device_type))


def bf16_status() -> str:
    """One line for `gymnast doctor`: whether this machine's CPU (and GPU, if any) runs bf16 natively."""
    def said(device_type: str) -> str:
        return "native, used" if bf16_is_native(device_type) else "emulated, float32 used instead"

    line = f"bf16 autocast: CPU {said('cpu')} ({torch.backends.cpu.get_cpu_capability()})"
    return line + (f"; GPU {said('cuda')}" if torch.cuda.is_available() else "")
