"""The kinds of environment a rollout runs in, each with what it declares about itself.

The RL loop, the env factory and the rewards read these declarations rather than comparing names:
whether a step is a real interaction (counted), whether the env reports success (a simulator's
verdict and per-step rewards, which the simulator rewards read), and whether its frames are imagined
by a world model (which then needs one, and can only continue real start frames, never set up a
scene). A run whose policy does not see the real world is also evaluated and watched there.

`ANCHORED` is both: the rollout happens in the real world, while the policy sees it through the
world model, which is restarted from the real frame every few actions
(`gymnast.envs.anchored`). It tells how long a policy can act on imagined frames before what it
learns stops carrying over to real ones: the imagined sight of the learning ladder, cut short.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

EnvName = Literal["imagined", "sim", "real", "anchored"]


@dataclass(frozen=True)
class EnvKind:
    """One kind of environment and what it declares.

    Attributes:
        name: how the command line and the saved run settings call it.
        real_interactions: each action is taken in the real world.
        reports_success: its steps report the task's success and a per-step reward (a simulator).
        imagined: its frames come from a world model, which it needs and which starts only from
            real frames.
    """

    name: EnvName
    real_interactions: bool
    reports_success: bool
    imagined: bool

    @property
    def real_sight(self) -> bool:
        """The policy sees the real world as it is: its own evaluation is the real one."""
        return self.real_interactions and not self.imagined

    def __str__(self) -> str:
        return self.name


IMAGINED = EnvKind("imagined", real_interactions=False, reports_success=False, imagined=True)
SIM = EnvKind("sim", real_interactions=False, reports_success=True, imagined=False)
REAL = EnvKind("real", real_interactions=True, reports_success=True, imagined=False)
ANCHORED = EnvKind("anchored", real_interactions=True, reports_success=True, imagined=True)
ENV_KINDS: dict[str, EnvKind] = {kind.name: kind for kind in (IMAGINED, SIM, REAL, ANCHORED)}


def env_kind(name: str) -> EnvKind:
    """The kind called `name`; ValueError naming the kinds otherwise."""
    if name not in ENV_KINDS:
        raise ValueError(f"unknown env {name!r}; the envs are {', '.join(ENV_KINDS)}")
    return ENV_KINDS[name]
