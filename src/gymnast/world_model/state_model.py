"""The grounded half of a world model: the robot's and the objects' state under the actions, and
what that state is worth.

Legend: B batch, T actions, S state dimensions, A action dimensions, E instruction embedding.

A video model alone does not know where the hand is: its imagined arm blurs within a few dozen
steps and ends centimetres from the real one, and a judge reading its frames then rewards what
the frames show, not what the actions did (docs/world_model.md). Every LeRobot dataset records
the robot's state (``observation.state``), and a simulator's datasets also the objects'
(``observation.environment_state``); success is decided there, in centimetres. This model
imagines that state step by step and reads the task's progress off it:

    s_{t+1} = s_t + sigma_delta * (mlp(s_t, s_0, a_t, a_{t-1}, e) + linear(s_t, s_0, a_t, a_{t-1}))
    reward_t, success_t = reward_head(s_{t+1}, s_0, e)

with s_0 the real start state (where the objects began: Meta-World's rewards measure progress
from there), a_t the action, a_{t-1} the one before (a position-controlled arm lags its command,
so where the hand goes next depends on the last command too, which no recorded state holds; at a
keyframe it is the last action of the prefix that led there) and e the instruction's sentence
embedding (which task's physics and goal). It is trained on the dataset's recorded states, per-step rewards (``next.reward``) and
success flags (``next.success``), unrolled through many steps so its own drift is in its training
distribution (`gymnast.world_model.train_state`). The reward head is what `gymnast rl --reward
state:RUN` practises on: a world model's own reward, read off its state instead of its pixels
(as Masked World Models and DreamerV3 read theirs off their latent state).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from torch import nn

from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import load_model, resolve_checkpoint
from gymnast.world_model.base import ActionScale, check_action_range

REWARD_SCALE = 10.0
"""Meta-World's largest per-step reward: rewards are learned divided by it (in [0, 1])."""


@dataclass(frozen=True)
class StateModelConfig:
    """Sizes of the state model; the data-dependent ones are set by training."""

    state_dim: int = 39
    """S: state dimensions (the dataset's environment state, else its ``observation.state``)."""
    action_dim: int = 4
    """A: action dimensions."""
    text_dim: int = 384
    """E: instruction embedding dimensions (`gymnast.policy.text.InstructionEncoder`)."""
    hidden: int = 256
    """Width of the dynamics and reward networks."""
    layers: int = 3
    """Hidden layers of the dynamics network (the reward head has two)."""
    last_action: bool = True
    """Condition each step on the action before it too (False: zeros in its place, the state alone)."""
    action_low: tuple[float, ...] = ()
    """(A,) the action mapped to -1 (the dataset's minimum; empty: actions already in [-1, 1])."""
    action_high: tuple[float, ...] = ()
    """(A,) the action mapped to +1."""

    def __post_init__(self) -> None:
        for name in ("state_dim", "action_dim", "text_dim", "hidden", "layers"):
            if getattr(self, name) < 1:
                raise ValueError(f"StateModelConfig.{name} must be at least 1, got {getattr(self, name)}")
        check_action_range(self.action_low, self.action_high, self.action_dim)


@dataclass(frozen=True)
class StateRollout:
    """What `StateModel.imagine` returns.

    Attributes:
        states: (B, T, S) the imagined state after each action.
        rewards: (B, T) the predicted per-step reward, in [0, 1] units of `REWARD_SCALE`.
        success: (B, T) the predicted probability that the task is achieved after each action.
    """

    states: torch.Tensor
    rewards: torch.Tensor
    success: torch.Tensor


def _mlp(inputs: int, hidden: int, layers: int, outputs: int) -> nn.Sequential:
    parts: list[nn.Module] = []
    for i in range(layers):
        parts += [nn.Linear(inputs if i == 0 else hidden, hidden), nn.SiLU()]
    return nn.Sequential(*parts, nn.Linear(hidden, outputs))


class StateModel(nn.Module):
    """See the module docstring. Normalisation statistics are buffers, saved with the weights."""

    def __init__(self, config: StateModelConfig) -> None:
        super().__init__()
        self.config = config
        s, e = config.state_dim, 64
        self.embed_text = nn.Linear(config.text_dim, e)
        inputs = 2 * s + 2 * config.action_dim
        self.dynamics = _mlp(inputs + e, config.hidden, config.layers, s)
        # Beside the network, a linear path that training starts at the least-squares fit of the
        # recorded steps (`gymnast.world_model.train_state.fit_linear_path`): the optimiser alone
        # does not find its large gains (docs/world_model.md).
        self.linear_dynamics = nn.Linear(inputs, s)
        self.reward_head = _mlp(2 * s + e, config.hidden, 2, 2)
        for layer in (self.dynamics[-1], self.linear_dynamics):  # starts as "nothing moves"
            nn.init.zeros_(layer.weight)
            nn.init.zeros_(layer.bias)
        self.scale_actions = ActionScale(config.action_low, config.action_high, config.action_dim)
        for name in ("state_mean", "delta_mean"):
            self.register_buffer(name, torch.zeros(s))
        for name in ("state_std", "delta_std"):
            self.register_buffer(name, torch.ones(s))

    def set_statistics(self, states: torch.Tensor, deltas: torch.Tensor) -> None:
        """Normalisation from (N, S) recorded states and (N, S) one-step changes; a dimension that
        never changes gets unit scale rather than a division by zero."""
        self.state_mean.copy_(states.mean(0))
        self.state_std.copy_(states.std(0).clamp_min(1e-3))
        self.delta_mean.copy_(deltas.mean(0))
        self.delta_std.copy_(deltas.std(0).clamp_min(1e-4))

    def _normal(self, states: torch.Tensor) -> torch.Tensor:
        return (states - self.state_mean) / self.state_std

    def next_state(self, state: torch.Tensor, start: torch.Tensor, action: torch.Tensor, last_action: torch.Tensor,
                   text: torch.Tensor) -> torch.Tensor:
        """(B, S) state after (B, A) `action` from (B, S) `state`, the action before being `last_action`
        (B, A); `start` (B, S), `text` (B, 64)."""
        inputs = self.linear_inputs(state, start, action, last_action)
        step = self.dynamics(torch.cat([inputs, text], dim=1)) + self.linear_dynamics(inputs)
        return state + self.delta_mean + self.delta_std * step

    def linear_inputs(self, state: torch.Tensor, start: torch.Tensor, action: torch.Tensor,
                      last_action: torch.Tensor) -> torch.Tensor:
        """(B, 2S + 2A) the dynamics' inputs besides the instruction, normalised."""
        before = self.scale_actions(last_action) if self.config.last_action else torch.zeros_like(action)
        return torch.cat([self._normal(state), self._normal(start), self.scale_actions(action), before], dim=1)

    def read_reward(self, state: torch.Tensor, start: torch.Tensor, text: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(reward (...,), success logit (...,)) of (..., S) states from (..., S) starts; `text` (..., 64)."""
        out = self.reward_head(torch.cat([self._normal(state), self._normal(start), text], dim=-1))
        return out[..., 0], out[..., 1]

    def unroll(self, start: torch.Tensor, actions: torch.Tensor, embedding: torch.Tensor,
               last_action: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Differentiable: (B, T, S) states, (B, T) rewards and (B, T) success logits after each of
        (B, T, A) `actions` from (B, S) real `start` states, reached by (B, A) `last_action` (None:
        zeros, a first frame); `embedding` (B, E) the instructions'."""
        text = self.embed_text(embedding)
        last_action = torch.zeros_like(actions[:, 0]) if last_action is None else last_action
        state, states = start, []
        for t in range(actions.shape[1]):
            state = self.next_state(state, start, actions[:, t], last_action, text)
            last_action = actions[:, t]
            states.append(state)
        states = torch.stack(states, dim=1)  # (B, T, S)
        steps = states.shape[1]
        rewards, logits = self.read_reward(states, start[:, None].expand(-1, steps, -1),
                                           text[:, None].expand(-1, steps, -1))
        return states, rewards, logits

    @torch.inference_mode()
    def imagine(self, start: torch.Tensor, actions: torch.Tensor, embedding: torch.Tensor,
                last_action: torch.Tensor | None = None) -> StateRollout:
        """`unroll` without gradients, with success as a probability."""
        last_action = None if last_action is None else last_action.float()
        states, rewards, logits = self.unroll(start.float(), actions.float(), embedding.float(), last_action)
        return StateRollout(states, rewards, torch.sigmoid(logits))

    @torch.inference_mode()
    def read(self, start: torch.Tensor, states: torch.Tensor, embedding: torch.Tensor) -> StateRollout:
        """The reward head on given (B, T, S) `states` (real ones) from (B, S) `start` states, with
        success as a probability: `imagine`'s reading without its dynamics."""
        text = self.embed_text(embedding.float())
        steps = states.shape[1]
        rewards, logits = self.read_reward(states.float(), start.float()[:, None].expand(-1, steps, -1),
                                           text[:, None].expand(-1, steps, -1))
        return StateRollout(states.float(), rewards, torch.sigmoid(logits))

    def spec(self) -> dict:
        """JSON-able description that `load_state_model` rebuilds the model from."""
        return asdict(self.config)


def load_state_model(run: str | Path) -> StateModel:
    """The newest checkpoint of a state-model run (or a checkpoint directory), in eval mode."""
    def build(spec: dict) -> StateModel:
        if "backend" in spec:  # a video model (a grounded one has a state_dim too)
            raise ValueError(f"{run} is not a state-model run: it holds a {spec['backend']} world model")
        if "state_dim" not in spec:
            raise ValueError(f"{run} is not a state-model run (its model has no state_dim: {sorted(spec)})")
        fields = {k: tuple(v) if k in ("action_low", "action_high") else v for k, v in spec.items()}
        return StateModel(StateModelConfig(**fields))

    return load_model(Path(run), build)


def load_state_models(run: str | Path) -> list[StateModel]:
    """The state models of `run`: one run, or an ensemble directory listing several
    (``ensemble.json``, as `gymnast make-ensemble` writes it), in member order.

    Raises:
        ValueError: the members do not take the same states and actions.
    """
    from gymnast.world_model.ensemble import is_ensemble, member_paths

    models = [load_state_model(path) for path in member_paths(run)] if is_ensemble(run) else [load_state_model(run)]
    return _fitting_together(models, str(run))


def is_state_model(run: str | Path) -> bool:
    """Whether `run` (a run or checkpoint directory) holds a state model rather than a video model."""
    try:
        spec = read_json(resolve_checkpoint(Path(run)) / "config.json").get("model", {})
    except (FileNotFoundError, ValueError):
        return False
    # A video model's spec names its backend (and a grounded one has a state_dim too).
    return isinstance(spec, dict) and "state_dim" in spec and "backend" not in spec


def write_state_ensemble(out: Path, members: Sequence[Path]) -> list[StateModel]:
    """Writes the ensemble directory `out` over state-model runs (see `load_state_models`); returns
    the members loaded.

    Raises:
        ValueError: fewer than two members, or they take different states or actions.
    """
    from gymnast.world_model.ensemble import write_manifest

    if len(members) < 2:
        raise ValueError(f"an ensemble needs two or more state-model runs, got {len(members)}")
    models = _fitting_together([load_state_model(member) for member in members], ", ".join(map(str, members)))
    write_manifest(out, members)
    return models


def _fitting_together(models: list[StateModel], where: str) -> list[StateModel]:
    """`models`, or ValueError naming `where` if they do not take the same states and actions."""
    shapes = {(m.config.state_dim, m.config.action_dim) for m in models}
    if len(shapes) > 1:
        raise ValueError(f"{where}: the state models take different (states, actions): {sorted(shapes)}")
    return models
