"""A reward as the command line names it, parsed once: `judge:RUN | state:RUN | vlm:MODEL@BASE_URL |
verified | sim | sim-dense`.

The command line parses the text into a `RewardSpec`; the library passes the spec on, builds the
reward from it (`gymnast.reward.select.make_reward`) and writes it back as text (`str(spec)`) only
where a person reads it: saved settings, summaries, reports. Light on purpose (no torch), since the
command line parses specs before it knows whether a model will be built.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

REWARD_FORMS = "judge:RUN | state:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense | all:REWARD+REWARD[+...]"

RewardKind = Literal["judge", "state", "vlm", "verified", "sim", "sim-dense", "all"]
_RUN_KINDS = ("judge", "state")  # named by their kind and a run directory
_PLAIN_KINDS = ("verified", "sim", "sim-dense")  # named by their kind alone


@dataclass(frozen=True)
class RewardSpec:
    """Which reward, and where its model lives.

    Attributes:
        kind: the reward's kind.
        run: the learned judge's run directory (``judge``), or the state model's (``state``: the
            reward head of a grounded world model, `gymnast.reward.state_reward`).
        model: the vision-language model's name (``vlm`` only).
        base_url: the OpenAI-compatible endpoint serving it (``vlm`` only).
        members: the rewards whose verdicts must all read success (``all`` only: a consensus,
            `gymnast.reward.consensus`), at least two, none a consensus itself.
    """

    kind: RewardKind
    run: Path | None = None
    model: str | None = None
    base_url: str | None = None
    members: tuple[RewardSpec, ...] = ()

    def __post_init__(self) -> None:
        complete = ({"vlm": bool(self.model and self.base_url), "all": len(self.members) >= 2}
                    | dict.fromkeys(_RUN_KINDS, self.run is not None))
        complete = complete.get(self.kind, True)
        if self.kind not in (*_PLAIN_KINDS, *_RUN_KINDS, "vlm", "all") or not complete:
            raise ValueError(f"unknown reward {self!r}; the forms are {REWARD_FORMS}")
        if any(member.kind == "all" for member in self.members):
            raise ValueError(f"a consensus of consensuses says nothing more: list every reward once ({REWARD_FORMS})")

    @classmethod
    def parse(cls, text: str) -> RewardSpec:
        """The spec `text` names (see `REWARD_FORMS`); ValueError listing the forms otherwise."""
        if text.startswith("all:"):
            parts = text.removeprefix("all:").split("+")
            if len(parts) < 2:
                raise ValueError(f"--reward {text}: a consensus names at least two rewards joined by +, e.g. "
                                 "all:judge:RUN+state:RUN")
            return cls("all", members=tuple(cls.parse(part) for part in parts))
        kind, _, argument = text.partition(":")
        if kind in _RUN_KINDS and argument:
            return cls(kind, run=Path(argument))
        model, _, base_url = argument.partition("@")
        if kind == "vlm" and model and base_url:
            return cls("vlm", model=model, base_url=base_url)
        if text in _PLAIN_KINDS:
            return cls(text)
        raise ValueError(f"unknown reward {text!r}; the forms are {REWARD_FORMS}")

    @classmethod
    def judge(cls, run: str | Path) -> RewardSpec:
        """The learned judge trained in `run`."""
        return cls("judge", run=Path(run))

    def __str__(self) -> str:
        if self.kind == "all":
            return "all:" + "+".join(str(member) for member in self.members)
        if self.kind in _RUN_KINDS:
            return f"{self.kind}:{self.run}"
        if self.kind == "vlm":
            return f"vlm:{self.model}@{self.base_url}"
        return self.kind
