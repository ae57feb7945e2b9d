"""The robot's state in imagination: a state model stepped beside the world model.

A video world model imagines frames only, but a policy that reads the robot's state (a LeRobot
policy's ``observation.state``) needs that state at every call. A state model
(`gymnast.world_model.state_model`) imagines it from each start's recorded state under the same
actions the world model is given, so `gymnast.envs.imagined.BatchedImaginedEnv`, given one
(``robot_state``), reports ``obs["state"]``: the first D dimensions of the imagined state. Meta-World's environment
state begins with the robot's (hand xyz and gripper opening: `gymnast.envs.metaworld.STATE_DIM`),
and a state model of another robot's dataset imagines its ``observation.state`` itself, so the
first D dimensions are the robot's state in both. An ensemble's members each step their own
rollout, and the robot state given is their mean.

Legend: B rollouts, S the state model's state dimensions, D the robot state's, A action
dimensions, k actions in one step.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from gymnast.policy.text import InstructionEncoder
from gymnast.world_model.state_model import StateModel


class ImaginedRobotState:
    """The robot's state of B imagined rollouts, stepped by one or more state models.

    Args:
        models: the state model, or an ensemble's members (`load_state_models`).
        dim: D, the robot state's dimensions the policy reads (the first D of the model's state).

    Raises:
        ValueError: no model, or a D the models' state does not have.
    """

    def __init__(self, models: StateModel | Sequence[StateModel], dim: int) -> None:
        self.models = [models] if isinstance(models, StateModel) else list(models)
        if not self.models:
            raise ValueError("an imagined robot state needs at least one state model")
        size = self.models[0].config.state_dim
        if not 0 < dim <= size:
            raise ValueError(f"the policy reads a {dim}-d robot state, the state model imagines {size}-d states")
        self.dim, self.encoder = dim, InstructionEncoder()
        self._start = self._last = torch.zeros(0)
        self._states: list[torch.Tensor] = []
        self._texts: list[torch.Tensor] = []

    @property
    def state_dim(self) -> int:
        """S, the state each rollout starts from (its recorded state)."""
        return self.models[0].config.state_dim

    @torch.inference_mode()
    def start(self, states: np.ndarray, last_actions: np.ndarray, instructions: Sequence[str]) -> np.ndarray:
        """(B, D) float32 the robot's state at the starts: (B, S) recorded states, each reached by
        its (B, A) last action (zeros at a first frame), under B instructions."""
        start = torch.as_tensor(np.asarray(states, np.float32))
        if start.ndim != 2 or start.shape[1] != self.state_dim or len(start) != len(instructions):
            raise ValueError(f"the imagined robot state starts from {len(instructions)} recorded states of "
                             f"{self.state_dim} dimensions, got {tuple(start.shape)}: starts that carry their state")
        embedding = self.encoder(list(instructions))
        self._start, self._last = start, torch.as_tensor(np.asarray(last_actions, np.float32))
        self._texts = [model.embed_text(embedding) for model in self.models]
        self._states = [start.clone() for _ in self.models]
        return self._robot()

    @torch.inference_mode()
    def step(self, actions: np.ndarray) -> np.ndarray:
        """(B, D) float32 the robot's state after (B, k, A) actions, one state-model step each."""
        for action in torch.as_tensor(np.asarray(actions, np.float32)).unbind(dim=1):  # (B, A) each
            self._states = [model.next_state(state, self._start, action, self._last, text)
                            for model, state, text in zip(self.models, self._states, self._texts)]
            self._last = action
        return self._robot()

    def _robot(self) -> np.ndarray:
        return torch.stack(self._states).mean(dim=0)[:, : self.dim].numpy()


def robot_state_in_imagination(state_dim: int, run: str | Path | None, policy: str | Path,
                               wm: str | Path | None) -> ImaginedRobotState | None:
    """What gives a policy that reads a `state_dim`-d robot state its state in imagination: the
    state model (or ensemble) in `run` (``--robot-state``), stepped beside the world model `wm`;
    None for a policy that reads none. Used alike by practice (`gymnast rl --env imagined`) and by
    the measurements of imagination (`gymnast imagination`, `gymnast rl-signal`).

    Raises:
        ValueError: a policy that reads a state without a state model, or a state model for a
            policy that reads none (the message names the policy and what to pass).
    """
    from gymnast.world_model.state_model import load_state_models

    if not state_dim:
        if run is not None:
            raise ValueError(f"--robot-state {run} imagines the robot's state for a policy that reads one; "
                             f"the policy {policy} reads none: leave --robot-state out")
        return None
    if run is None:
        raise ValueError(f"the policy {policy} reads the robot's state (observation.state, {state_dim}-d), but the "
                         f"world model {wm} imagines images only; give a state model that imagines it with "
                         "--robot-state RUN (gymnast train-state)")
    return ImaginedRobotState(load_state_models(run), state_dim)
