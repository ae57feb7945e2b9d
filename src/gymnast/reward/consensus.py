"""A verdict only where several rewards agree: success where every member reads success.

Legend: B rollouts, T frames, M members.

A policy practising in a world model drifts to what the model gets wrong: its actions, chosen on
imagined frames, come to be correlated with the model's errors, and a judge of the imagined video
then calls them successes. Two models that err differently (a pixel judge on the imagined video and
the state model's reward head on states imagined from the same actions, say) are unlikely to be
fooled by the same actions, so a success both read is more likely real; where they disagree the
rollout counts as a failure. `--reward all:judge:RUN+state:RUN` names one.

Each member gives a 0/1 verdict: a binary reward's score, or a continuous reward's own reading of
success (`VerdictReward`, the state model's). A NaN from any member (could not score) is NaN.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from gymnast.reward.base import Reward, RewardContext, RewardNeeds, VerdictReward, read_verdict


class ConsensusReward:
    """`Reward`: 1.0 where every member reads success, else 0.0 (binary).

    Args:
        members: the rewards (at least two), each binary or a `VerdictReward`.
        names: what the command line called each, for messages and metrics.

    Raises:
        ValueError: fewer than two members, or a member that gives no verdict.
    """

    binary = True

    def __init__(self, members: Sequence[Reward], names: Sequence[str]) -> None:
        if len(members) < 2 or len(members) != len(names):
            raise ValueError(f"a consensus needs at least two rewards, got {list(names)}")
        for member, name in zip(members, names):
            if not member.binary and not isinstance(member, VerdictReward):
                raise ValueError(f"--reward {name} gives degrees, not a verdict of success: a consensus takes judges, "
                                 "the state model (state:RUN), a VLM or the simulator's success")
        self.members, self.names = list(members), list(names)
        self.needs = RewardNeeds(**{field: any(getattr(m.needs, field) for m in members)
                                    for field in ("world_model", "simulator_success", "reference_actions", "start_state",
                                                  "video")})
        self._agreed, self._scored = 0, 0  # since the last `metrics()`: a step's groups are scored one at a time

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        """(B,) 1.0 where every member reads success, 0.0 where one does not, NaN where one could not score."""
        verdicts = torch.stack([read_verdict(member, frames, instructions, context) for member in self.members])  # (M, B)
        scored = torch.isfinite(verdicts).all(dim=0)  # (B,)
        said = verdicts[:, scored] > 0.5  # (M, B')
        self._agreed += int((said.all(dim=0) | ~said.any(dim=0)).sum())
        self._scored += int(scored.sum())
        agreed = verdicts.amin(dim=0)
        return torch.where(scored, agreed, torch.full_like(agreed, float("nan")))

    def to(self, device):
        """Moves the members that are modules (learned judges) to `device`."""
        for member in self.members:
            if isinstance(member, torch.nn.Module):
                member.to(device)
        return self

    def metrics(self) -> dict[str, float]:
        """``reward/consensus_agreement``: the share of the rollouts scored since the last call whose
        members agreed; and every member's own metrics."""
        values = {"reward/consensus_agreement": self._agreed / self._scored} if self._scored else {}
        self._agreed, self._scored = 0, 0
        for member in self.members:
            values |= member.metrics()
        return values
