"""Importing LeRobot beside gymnast's torch: the one place that does it.

lerobot 0.4.4 pins torch < 2.11 while gymnast runs on 2.11 and newer, so it is installed without
its dependencies (`pip install --no-deps lerobot==0.4.4`, after `pip install
'world-gymnast[lerobot]'`, which brings what its policies import). One more thing can stand in
the way: a torchvision whose compiled operators do not load beside this torch (PyPI's torchvision
wheels are CUDA builds; with the CPU build of torch their extension fails to load), and then
``import torchvision`` fails on registering a fake kernel for ``torchvision::nms``, an operator
that was never defined. Defining the schemas of its two such operators first lets it import;
LeRobot's policies use only its pure-PyTorch parts (backbones, transforms), and those work
(`gymnast.utils.torchvision_ops`).
"""

from __future__ import annotations

import functools

from gymnast.utils.torchvision_ops import allow_torchvision_import

LEROBOT_VERSION = "0.4.4"
"""The lerobot release the adapter is written against and tested with."""

INSTALL = ("pip install 'world-gymnast[lerobot]' && pip install --no-deps "
           f"lerobot=={LEROBOT_VERSION}")
"""How a user installs LeRobot beside gymnast (docs/lerobot.md says why in two steps)."""


@functools.lru_cache(maxsize=1)
def require_lerobot() -> None:
    """Makes ``import lerobot`` work, or says how to install it.

    Raises:
        ImportError: lerobot (or what its policies import) is missing; the message names the
            install command.
    """
    allow_torchvision_import()
    try:
        import lerobot.policies  # noqa: F401  (the package's own imports are what can fail)
    except ImportError as error:
        raise ImportError(f"--policy lerobot:PATH needs LeRobot {LEROBOT_VERSION} beside gymnast ({error}); "
                          f"install it with: {INSTALL}") from error
