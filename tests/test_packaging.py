"""The library's torch requirement lets a GPU user keep their CUDA build; the set-up pins the CPU one."""

import re
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]


def _torch_requirement() -> Requirement:
    dependencies = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    return next(Requirement(d) for d in dependencies if Requirement(d).name == "torch")


def test_a_users_cuda_build_of_torch_satisfies_the_library():
    specifier = _torch_requirement().specifier
    for version in ("2.11.0+cu130", "2.12.1+cu128", "2.13.0"):
        assert specifier.contains(version), f"torch {version} is refused by {specifier}"


def test_the_set_up_commands_pin_the_cpu_build_within_the_range():
    pinned = re.search(r"^TORCH_CPU := torch==(\S+)$", (ROOT / "Makefile").read_text(), re.MULTILINE)
    assert pinned, "the Makefile no longer pins torch's CPU build"
    assert _torch_requirement().specifier.contains(pinned.group(1))
