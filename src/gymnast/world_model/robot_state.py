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

A grounded world model (`gymnast.world_model.embedded`, ``state_dim`` S) renders every frame at a
state: the env gives it this object's whole imagined state after each action (`imagine`), so the
frames show where the state model says things are, and a policy that reads the robot's state reads
the same rollout's. With a policy that reads none, D is 0 and the env reports no state.

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
        dim: D, the robot state's dimensions the policy reads (the first D of the model's state);
            0 where only a grounded world model reads the state.

    Raises:
        ValueError: no model, or a D the models' state does not have.
    """

    def __init__(self, models: StateModel | Sequence[StateModel], dim: int) -> None:
        self.models = [models] if isinstance(models, StateModel) else list(models)
        if not self.models:
            raise ValueError("an imagined robot state needs at least one state model")
        size = self.models[0].config.state_dim
        if not 0 <= dim <= size:
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
        return self.robot()

    def step(self, actions: np.ndarray) -> np.ndarray:
        """(B, D) float32 the robot's state after (B, k, A) actions, one state-model step each."""
        self.imagine(actions)
        return self.robot()

    @torch.inference_mode()
    def imagine(self, actions: np.ndarray) -> torch.Tensor:
        """Steps the rollouts by (B, k, A) actions; returns (B, k, S) float32 the whole imagined state
        after each (the members' mean), what a grounded world model renders its k frames at."""
        after = []
        for action in torch.as_tensor(np.asarray(actions, np.float32)).unbind(dim=1):  # (B, A) each
            self._states = [model.next_state(state, self._start, action, self._last, text)
                            for model, state, text in zip(self.models, self._states, self._texts)]
            self._last = action
            after.append(torch.stack(self._states).mean(dim=0))
        return torch.stack(after, dim=1)

    def robot(self) -> np.ndarray:
        """(B, D) float32 the robot's state now (the members' mean)."""
        return torch.stack(self._states).mean(dim=0)[:, : self.dim].numpy()


def robot_state_in_imagination(state_dim: int, run: str | Path | None, policy: str | Path,
                               wm: str | Path | None, grounded: int = 0) -> ImaginedRobotState | None:
    """What imagines the state beside the world model `wm`: the state model (or ensemble) in `run`
    (``--robot-state``), for a policy that reads a `state_dim`-d robot state and/or a world model
    grounded in a `grounded`-d state (S > 0, which it renders every frame at); None where neither
    reads one. Used alike by practice (`gymnast rl --env imagined`) and by the measurements of
    imagination (`gymnast imagination`, `gymnast rl-signal`).

    Raises:
        ValueError: a state needed without a state model, a state model nothing reads, or one whose
            state is not the grounded world model's (the message names the runs and what to pass).
    """
    from gymnast.world_model.state_model import load_state_models

    if not state_dim and not grounded:
        if run is not None:
            raise ValueError(f"--robot-state {run} imagines the state that a policy or a grounded world model reads; "
                             f"the world model {wm} is not grounded and the policy {policy} reads none: leave --robot-state out")
        return None
    if run is None:
        reader = (f"the world model {wm} renders every frame at a {grounded}-d state" if grounded else
                  f"the policy {policy} reads the robot's state (observation.state, {state_dim}-d), but the "
                  f"world model {wm} imagines images only")
        raise ValueError(f"{reader}; give a state model that imagines it with --robot-state RUN (gymnast train-state)")
    imagined = ImaginedRobotState(load_state_models(run), state_dim)
    if grounded and imagined.state_dim != grounded:
        raise ValueError(f"the world model {wm} renders at {grounded}-d states, the state model {run} imagines "
                         f"{imagined.state_dim}-d ones: train both on the same dataset's states")
    return imagined
