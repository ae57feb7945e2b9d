"""The states a grounded world model renders at when it is measured outside the imagined env.

A grounded model (`gymnast.world_model.embedded`, ``state_dim`` S > 0) draws every frame at a
state it is given. In RL the imagined env gives it a state model's states
(`gymnast.world_model.robot_state`); `gymnast eval-wm` measures it both ways:

- at the recorded states (no state model): what it would draw beside a perfect state model, the
  most grounding can give;
- at a state model's states (``--robot-state RUN``), imagined from each rollout's real start
  under the same actions: what practice gets.

Legend: N rollouts, T actions, S state dimensions, A action dimensions.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from gymnast.world_model.robot_state import ImaginedRobotState
from gymnast.world_model.state_model import StateModel


class StateSource:
    """Where a grounded world model's states come from: the recorded ones, or a state model's.

    Args:
        models: the state model (or an ensemble's members) that imagines them; None: the recorded states.
    """

    def __init__(self, models: Sequence[StateModel] | None = None) -> None:
        self._imagined = ImaginedRobotState(models, 0) if models else None

    @property
    def name(self) -> str:
        """How the report names the states used."""
        return "recorded" if self._imagined is None else "state_model"

    def states(self, start: np.ndarray, last_action: np.ndarray, instruction: str, actions: np.ndarray,
               recorded: np.ndarray) -> torch.Tensor:
        """(N, T, S) float32 the states to render N rollouts' frames at.

        Args:
            start: (S,) the recorded state the rollouts start from.
            last_action: (A,) the action that led there (zeros at a first frame).
            instruction: the episode's instruction (a state model reads it).
            actions: (N, T, A) the rollouts' actions.
            recorded: (N, T, S) the real states after each action (the simulator's or the dataset's).
        """
        if self._imagined is None:
            return torch.as_tensor(np.asarray(recorded, np.float32))
        count = len(actions)
        self._imagined.start(np.repeat(start[None], count, 0), np.repeat(last_action[None], count, 0), [instruction] * count)
        return self._imagined.imagine(np.asarray(actions, np.float32))
