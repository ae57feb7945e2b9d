"""The device a command runs its models on, resolved once and passed in (modules store none).

``auto`` is CUDA when torch sees a GPU and the CPU otherwise; asking for CUDA where there is none
is an error that says so, not a silent fall back. Models move to the device; the environments,
datasets and rollout records stay on the host, and batches are copied over as they are used
(non-blocking from the host to a GPU).
"""

from __future__ import annotations

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
