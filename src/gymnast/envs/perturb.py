"""Initial-state perturbations for robustness tests, in centimetres, after VLA-RFT.

VLA-RFT perturbs the object position, the goal position and the robot's initial state by 2.5 cm
(minor) or 5 cm (major), separately and all together. Here a perturbation moves each chosen
thing by exactly that distance in a random direction (in the table plane for the object and the
goal; in 3-D for the hand), away from the position the unperturbed (task, seed) would give.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LEVELS_CM: dict[str, float] = {"none": 0.0, "minor": 2.5, "major": 5.0}
TARGETS = ("object", "goal", "robot", "all")


@dataclass(frozen=True)
class Perturbation:
    """Which part of the initial state moves, and by how much.

    Attributes:
        level: ``none``, ``minor`` (2.5 cm) or ``major`` (5 cm).
        target: ``object``, ``goal``, ``robot`` (the hand's start) or ``all`` three.
    """

    level: str = "none"
    target: str = "all"

    def __post_init__(self) -> None:
        if self.level not in LEVELS_CM:
            raise ValueError(f"perturbation level must be one of {tuple(LEVELS_CM)}, got {self.level!r}")
        if self.target not in TARGETS:
            raise ValueError(f"perturbation target must be one of {TARGETS}, got {self.target!r}")

    @property
    def distance_m(self) -> float:
        return LEVELS_CM[self.level] / 100.0

    @property
    def active(self) -> bool:
        return self.level != "none"

    def moves(self, part: str) -> bool:
        """Whether this perturbation moves `part` (``object``, ``goal`` or ``robot``)."""
        return self.active and self.target in (part, "all")


def get_perturbation(spec: str | Perturbation) -> Perturbation:
    """Parses ``"minor"``, ``"major:object"`` or ``"none"`` (or passes a Perturbation through)."""
    if isinstance(spec, Perturbation):
        return spec
    level, _, target = spec.partition(":")
    return Perturbation(level=level, target=target or "all")


def random_offset(rng: np.random.Generator, distance: float, planar: bool) -> np.ndarray:
    """A (3,) vector of length `distance` in a uniformly random direction (z = 0 if planar)."""
    if planar:
        angle = rng.uniform(0.0, 2.0 * np.pi)
        return distance * np.array([np.cos(angle), np.sin(angle), 0.0])
    direction = rng.normal(size=3)
    return distance * direction / np.linalg.norm(direction)
