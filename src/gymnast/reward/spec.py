"""A reward as the command line names it, parsed once: `judge:RUN | vlm:MODEL@BASE_URL | verified |
sim | sim-dense`.

The command line parses the text into a `RewardSpec`; the library passes the spec on, builds the
reward from it (`gymnast.reward.select.make_reward`) and writes it back as text (`str(spec)`) only
where a person reads it: saved settings, summaries, reports. Light on purpose (no torch), since the
command line parses specs before it knows whether a model will be built.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

REWARD_FORMS = "judge:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense"

RewardKind = Literal["judge", "vlm", "verified", "sim", "sim-dense"]
_PLAIN_KINDS = ("verified", "sim", "sim-dense")  # named by their kind alone


@dataclass(frozen=True)
class RewardSpec:
    """Which reward, and where its model lives.

    Attributes:
        kind: the reward's kind.
        run: the learned judge's run directory (``judge`` only).
        model: the vision-language model's name (``vlm`` only).
        base_url: the OpenAI-compatible endpoint serving it (``vlm`` only).
    """

    kind: RewardKind
    run: Path | None = None
    model: str | None = None
    base_url: str | None = None

    def __post_init__(self) -> None:
        complete = {"judge": self.run is not None, "vlm": bool(self.model and self.base_url)}.get(self.kind, True)
        if self.kind not in (*_PLAIN_KINDS, "judge", "vlm") or not complete:
            raise ValueError(f"unknown reward {self!r}; the forms are {REWARD_FORMS}")

    @classmethod
    def parse(cls, text: str) -> RewardSpec:
        """The spec `text` names (see `REWARD_FORMS`); ValueError listing the forms otherwise."""
        kind, _, argument = text.partition(":")
        if kind == "judge" and argument:
            return cls("judge", run=Path(argument))
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
        if self.kind == "judge":
            return f"judge:{self.run}"
        if self.kind == "vlm":
            return f"vlm:{self.model}@{self.base_url}"
        return self.kind
