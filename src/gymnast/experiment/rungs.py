"""The rungs of the learning ladder (`gymnast.experiment.ladder`): which env the policy acts in,
who rewards it and what that reward sees."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from gymnast.envs.kinds import IMAGINED, REAL, EnvKind

REWARDS = ("sim", "judge", "state")
"""Who gives a rung's reward: the simulator's success, the learned judge or the state model."""


@dataclass(frozen=True)
class Rung:
    """One rung: which env the policy acts in, who rewards it and what that reward sees.

    Attributes:
        name: the rung's key in summary.json and its run directory.
        env: where the rollouts run (and so what the policy sees).
        reward: who gives the reward (one of `REWARDS`; the fixed arm's is its whole reward spec).
        sees: where the reward's video comes from (None: the rollouts' own).
        what: the rung in words, for the report.
        own_start: a fix arm that starts from another policy than the ladder's: its step 0 is
            not the ladder's starting policy.
    """

    name: str
    env: EnvKind
    reward: str
    sees: EnvKind | None
    what: str
    own_start: bool = False

    @property
    def needs_world_model(self) -> bool:
        return self.env.imagined or (self.sees is not None and self.sees.imagined)


RUNGS: dict[str, Rung] = {rung.name: rung for rung in (
    Rung("r0_real", REAL, "sim", None, "reality: rendered frames, real dynamics, the simulator's success"),
    Rung("r1_judge_real", REAL, "judge", None, "the judge's verdict on the real video"),
    Rung("r1s_state_real", REAL, "state", None, "the state model's reward head on the real states of the real rollouts"),
    Rung("r2_imagined_verdict", REAL, "judge", IMAGINED,
         "the policy acts for real; the judge scores the world model's re-imagining of the same actions"),
    Rung("r3_imagined_sight", IMAGINED, "sim", REAL,
         "the policy acts on imagined frames; its actions replayed for real give the simulator's success"),
    Rung("r4_imagined", IMAGINED, "judge", None, "imagination: imagined frames, the judge on imagined video"),
    Rung("r4s_imagined_state", IMAGINED, "state", None, "imagination with the state model's reward"),
)}


FIXED = Rung("fixed", IMAGINED, "", None, "the practice arm after the fix")
"""Where a ladder keeps the practice arm after the fix: OUT/fixed (and OUT/fixed_<lever> for other
levers tried), a `gymnast rl` run with the ladder's recipe and whatever lever mends the rung where
learning died (its env and reward are read from its own settings)."""


def rung_dir(out: Path, rung: Rung) -> Path:
    """Where a ladder in `out` runs `rung`."""
    return out / rung.name
