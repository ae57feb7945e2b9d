"""A consensus of rewards: success only where every member reads success, against hand-made verdicts."""

from collections.abc import Sequence

import pytest
import torch

from gymnast.envs.kinds import IMAGINED, REAL
from gymnast.reward.base import RewardContext, RewardNeeds, check_fits
from gymnast.reward.consensus import ConsensusReward
from gymnast.reward.sim import SimDense, SimSuccess


class _Fixed:
    """A binary reward with fixed scores (NaN: could not score)."""

    binary = True
    needs = RewardNeeds()

    def __init__(self, scores: list[float]) -> None:
        self.scores = torch.tensor(scores)

    def score(self, frames: torch.Tensor, instructions: Sequence[str], context: RewardContext) -> torch.Tensor:
        return self.scores

    def metrics(self) -> dict[str, float]:
        return {}


class _Reading:
    """A continuous reward that reads a verdict of its own (as the state model's does)."""

    binary = False
    needs = RewardNeeds(start_state=True)

    def __init__(self, verdicts: list[float]) -> None:
        self.verdicts = torch.tensor(verdicts)

    def score(self, frames, instructions, context):
        return self.verdicts * 0.3

    def verdict(self, instructions, context):
        return self.verdicts

    def metrics(self):
        return {}


def test_success_only_where_every_member_reads_it_and_nan_where_one_could_not_score():
    reward = ConsensusReward([_Fixed([1.0, 1.0, 0.0, 0.9, 1.0]), _Reading([1.0, 0.0, 0.0, 1.0, float("nan")])],
                             ["judge:a", "state:b"])
    scores = reward.score(torch.zeros(5, 2, 4, 4, 3, dtype=torch.uint8), ["t"] * 5, RewardContext())
    assert scores[:4].tolist() == [1.0, 0.0, 0.0, 1.0] and scores[4].isnan()
    reward.score(torch.zeros(5, 2, 4, 4, 3, dtype=torch.uint8), ["t"] * 5, RewardContext())  # a step's next group
    assert reward.metrics()["reward/consensus_agreement"] == 0.75  # they differ on the second of four, each time
    assert reward.metrics() == {}  # counted afresh after each report
    assert reward.binary and reward.needs.start_state and reward.needs.video


def test_a_consensus_needs_what_any_member_needs():
    reward = ConsensusReward([SimSuccess(), _Fixed([1.0])], ["sim", "judge:a"])
    check_fits(reward, "all:sim+judge:a", REAL)
    with pytest.raises(ValueError, match="simulator"):
        check_fits(reward, "all:sim+judge:a", IMAGINED)


def test_a_member_without_a_verdict_or_a_lone_member_is_refused():
    with pytest.raises(ValueError, match="gives degrees"):
        ConsensusReward([SimDense(), _Fixed([1.0])], ["sim-dense", "judge:a"])
    with pytest.raises(ValueError, match="at least two"):
        ConsensusReward([_Fixed([1.0])], ["judge:a"])
