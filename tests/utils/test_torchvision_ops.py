"""torchvision, where installed, imports beside the CPU build of torch, and so does transformers
(the instruction encoder's), which imports it."""

from __future__ import annotations

import importlib.util
import subprocess
import sys


def test_transformers_and_torchvision_import_after_the_operators_are_allowed():
    # A fresh interpreter: whether torchvision imports is decided once per process.
    script = ("from gymnast.utils.torchvision_ops import allow_torchvision_import\n"
              "allow_torchvision_import()\n"
              "from transformers import PreTrainedModel\n"
              "import importlib.util\n"
              "if importlib.util.find_spec('torchvision'):\n"
              "    import torchvision.models, torchvision.transforms\n"
              "    torchvision.models.resnet18(weights=None)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


def test_nothing_is_declared_without_torchvision_or_once_it_is_imported(monkeypatch):
    from gymnast.utils import torchvision_ops

    torchvision_ops.allow_torchvision_import.cache_clear()
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    assert torchvision_ops.allow_torchvision_import() is False
    torchvision_ops.allow_torchvision_import.cache_clear()
