"""Lets an installed torchvision import beside a torch it was not built for.

The package index serves torch's CPU build, but torchvision's wheels are built for CUDA: beside the
CPU torch, torchvision's compiled operators (``torchvision/_C``) fail to load, and the import then
fails too, with "operator torchvision::nms does not exist", because torchvision registers a
Python fake kernel for ``nms`` without checking that its extension loaded. Whatever imports
torchvision then breaks with it: transformers (the instruction encoder), LeRobot's policies.

Defining the two operator schemas it expects before the import is enough: torchvision then
imports, reports its compiled operators as unavailable, and its pure-PyTorch parts (the models,
the transforms) work. Where the extension does load, nothing is done.
"""

from __future__ import annotations

import functools
import importlib.util
import sys
from pathlib import Path

import torch

_SCHEMAS = ("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor",
            "qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")


@functools.lru_cache(maxsize=1)
def allow_torchvision_import() -> bool:
    """Makes ``import torchvision`` work (see the module docstring); call before anything imports it.

    Returns:
        True where torchvision's operators had to be declared (its extension does not load here),
        False where nothing was needed: torchvision absent, already imported, or loading fine.
    """
    spec = importlib.util.find_spec("torchvision")
    if spec is None or spec.origin is None or "torchvision" in sys.modules:
        return False
    folder = Path(spec.origin).parent
    extension = next(iter(sorted(folder.glob("_C*.so")) + sorted(folder.glob("_C*.pyd"))), None)
    if extension is not None:
        try:
            torch.ops.load_library(str(extension))
            return False
        except OSError:
            pass  # built for another torch (or for CUDA): declare what its Python side expects
    library = torch.library.Library("torchvision", "DEF")
    for schema in _SCHEMAS:
        try:
            library.define(schema)
        except RuntimeError:  # already declared in this process by its user: nothing to add
            pass
    _KEPT.append(library)  # the declarations last as long as the Library object does
    return True


_KEPT: list[torch.library.Library] = []
