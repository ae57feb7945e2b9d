"""The `WorldModel` contract: an action-conditioned video model the policy can practise in.

Legend: B batch, C context frames, T imagined steps, K actions per `step` call, H/W image size,
A action dimensions.

A world model starts from real context frames and imagines one frame per action:

    state = model.init_state(context)            # context (B, C', H, W, 3) uint8, any 1 <= C'
    state, frames = model.step(state, actions)   # actions (B, K, A) -> frames (B, K, H, W, 3) uint8

The state is explicit and opaque (whatever the backend needs), so many rollouts can run side by
side and a rollout can be branched. Frames are uint8 like the real camera's, so the policy, the
reward and the videos never know where they came from. `rollout` imagines fixed actions
open-loop (fidelity evaluation, verified rewards, judge training). Closed-loop rollouts, where a
policy chooses each chunk from the imagined frames (RL, plans made in imagination), run in
`gymnast.envs.imagined.BatchedImaginedEnv`, driven by the rollout engine like every other env
(`gymnast.envs.engine.run_batch`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import torch

from gymnast.utils.checkpoint import load_model
from gymnast.utils.device import bf16_autocast, module_device, to_device
from gymnast.utils.plugins import import_named, is_plugin, load_plugin, missing_attributes


class WorldModel(Protocol):
    """An action-conditioned video model over uint8 RGB frames."""

    context_frames: int  # C: the real frames `init_state` uses (the most recent C of those given)
    image_size: int  # H = W of one camera's view
    action_dim: int  # A
    # A model of V cameras (`gymnast.world_model.views`) also has `views` (V) and `cameras` (their
    # names), and its frames are (..., H, V*W, 3), the views side by side; one without them sees one.
    # A grounded model has `state_dim` S > 0 and its `step` takes ``states``, (B, K, S) the state
    # each frame is rendered at (`grounded_state_dim`); one without it follows the actions alone.
    # A model that imagines one frame per chunk of N actions has `actions_per_frame` N > 1: the frame
    # after a chunk's last action is imagined, the others repeat the last imagined one
    # (`imagined_frame_mask`); actions that do not fill a chunk wait for the next `step` call.

    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> Any:
        """State after the real (B, C', H, W, 3) uint8 context frames, the last one being "now".

        Fewer than C frames are allowed (a single start frame is the usual case): the first one is
        repeated, as if the robot had been standing still.
        """
        ...

    def step(self, state: Any, actions: torch.Tensor, generator: torch.Generator | None = None) -> tuple[Any, torch.Tensor]:
        """Applies (B, K, A) actions in order; returns the new state and (B, K, H, W, 3) uint8 frames."""
        ...


def check_context(context: torch.Tensor, image_size: int, views: int = 1) -> None:
    """Raises ValueError unless `context` is (B, C, H, V*W, 3) uint8 with C >= 1, H = W = image_size
    and V = views (the cameras side by side, `gymnast.world_model.views`)."""
    width = views * image_size
    expected = f"(B, C, {image_size}, {width}, 3) uint8" + (f" ({views} views side by side)" if views > 1 else "")
    if not isinstance(context, torch.Tensor):
        raise ValueError(f"context frames must be a tensor {expected}, got {type(context).__name__}")
    if context.ndim != 5 or tuple(context.shape[2:]) != (image_size, width, 3) or context.shape[1] < 1:
        raise ValueError(f"context frames must be {expected}, got {tuple(context.shape)}")
    if context.dtype != torch.uint8:
        raise ValueError(f"context frames must be {expected}, got dtype {context.dtype}")


def check_actions(actions: torch.Tensor, action_dim: int, batch: int) -> None:
    """Raises ValueError unless `actions` is (batch, K, action_dim) floating point with K >= 1."""
    expected = f"({batch}, K, {action_dim}) float"
    if not isinstance(actions, torch.Tensor):
        raise ValueError(f"actions must be a tensor {expected}, got {type(actions).__name__}")
    if actions.ndim != 3 or actions.shape[0] != batch or actions.shape[2] != action_dim or actions.shape[1] < 1:
        raise ValueError(f"actions must be {expected}, got {tuple(actions.shape)}")
    if not actions.is_floating_point():
        raise ValueError(f"actions must be {expected}, got dtype {actions.dtype}")


def grounded_state_dim(model: Any) -> int:
    """S, the state a grounded world model renders every frame at; 0 for one that is not grounded."""
    return int(getattr(model, "state_dim", 0))


def actions_per_frame(model: Any) -> int:
    """N, the actions of one imagined frame: 1 for a model that imagines a frame per action."""
    return int(getattr(model, "actions_per_frame", 1))


def imagined_frame_mask(model: Any, frames: int) -> torch.Tensor:
    """(frames,) bool: which of the frames a rollout from a fresh state returns are imagined, not a
    repeat of the last one: every N-th (`actions_per_frame`), so all of them for N = 1. What the
    frames' quality is measured on."""
    return every_nth_frame(frames, actions_per_frame(model))


def every_nth_frame(frames: int, n: int) -> torch.Tensor:
    """(frames,) bool: True at the frames after actions n, 2n, ... of a rollout."""
    return (torch.arange(frames) + 1) % n == 0


def check_states(states: torch.Tensor | None, state_dim: int, leading: tuple[int, ...]) -> None:
    """Raises ValueError unless `states` is None for a model that is not grounded (`state_dim` 0),
    or (B, K, state_dim) floating point, (B, K) = `leading`, for a grounded one."""
    if not state_dim:
        if states is not None:
            raise ValueError("this world model is not grounded in a state (state_dim 0); it takes no states")
        return
    expected = f"({', '.join(map(str, leading))}, {state_dim}) float: the state each frame is rendered at"
    if states is None:
        raise ValueError(f"this world model is grounded: step() needs states {expected} (a state model imagines them, "
                         "gymnast.world_model.robot_state)")
    if not isinstance(states, torch.Tensor) or tuple(states.shape) != (*leading, state_dim) or not states.is_floating_point():
        got = tuple(states.shape) if isinstance(states, torch.Tensor) else type(states).__name__
        raise ValueError(f"states must be {expected}, got {got}")


def pad_context(context: torch.Tensor, frames: int) -> torch.Tensor:
    """The last `frames` of (B, C', H, W, 3), repeating the first frame in front when C' is short."""
    missing = frames - context.shape[1]
    if missing > 0:
        context = torch.cat([context[:, :1].expand(-1, missing, -1, -1, -1), context], dim=1)
    return context[:, -frames:]


def check_action_range(low: tuple[float, ...], high: tuple[float, ...], action_dim: int) -> None:
    """Raises ValueError unless (low, high) is empty or gives every action dimension a low below its high."""
    if len(low) != len(high) or (low and len(low) != action_dim):
        raise ValueError(f"action_low and action_high need {action_dim} values each (action_dim) or none, "
                         f"got {len(low)} and {len(high)}")
    if any(h <= lo for lo, h in zip(low, high)):
        raise ValueError(f"every action_high must exceed its action_low, got {low} / {high}")


class ActionScale(torch.nn.Module):
    """Maps each action dimension's [low, high] (the training data's range) onto [-1, 1], the
    scale the network's inputs were trained at; the identity for an empty range (models saved
    before ranges were recorded, whose actions were Meta-World's, already in [-1, 1]).

    Its buffers are not saved: the range lives in the model's config, so checkpoints keep their keys.
    """

    def __init__(self, low: tuple[float, ...], high: tuple[float, ...], action_dim: int) -> None:
        super().__init__()
        check_action_range(low, high, action_dim)
        self.action_dim, self.scaled = action_dim, bool(low)
        self.low, self.high = low, high
        if low:
            lo, hi = torch.tensor(low), torch.tensor(high)
            self.register_buffer("centre", (hi + lo) / 2, persistent=False)  # (A,)
            self.register_buffer("half_range", (hi - lo) / 2, persistent=False)  # (A,)

    @property
    def bounds(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(low, high) per action dimension; [-1, 1] for the identity."""
        return (self.low, self.high) if self.scaled else ((-1.0,) * self.action_dim, (1.0,) * self.action_dim)

    def forward(self, actions: torch.Tensor) -> torch.Tensor:
        """(..., A) actions in the data's units -> the same in [-1, 1]."""
        return (actions - self.centre) / self.half_range if self.scaled else actions


class ConfiguredWorldModel(torch.nn.Module):
    """What every backend built from a frozen config dataclass shares: its sizes and action range
    read off the config, bfloat16 autocast, and a JSON spec that rebuilds it (`load_world_model`).

    A subclass names its `backend` and `config_class`, sets `self.config` and builds
    `self.scale_actions` (an `ActionScale` of the config's range).
    """

    backend: str
    config_class: type
    _TUPLES = ("widths", "action_low", "action_high", "state_mean", "state_std")  # config fields that JSON keeps as lists

    @property
    def context_frames(self) -> int:
        return self.config.context_frames

    @property
    def image_size(self) -> int:
        return self.config.image_size

    @property
    def action_dim(self) -> int:
        return self.config.action_dim

    @property
    def action_range(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(low, high) per action dimension: the range the training data's actions spanned (what
        the imagined env's action space allows), [-1, 1] for models saved before it was recorded."""
        return self.scale_actions.bounds

    def autocast(self):
        """bfloat16 autocast on the model's device when the config asks for it and the device computes
        bfloat16 natively (else a no-op context)."""
        return bf16_autocast(next(self.parameters()).device, self.config.bf16)

    def spec(self) -> dict:
        """JSON-able description that `from_spec` rebuilds the model from."""
        return {"backend": self.backend, **asdict(self.config)}

    @classmethod
    def from_spec(cls, spec: dict):
        fields = {k: tuple(v) if k in cls._TUPLES else v for k, v in spec.items() if k != "backend"}
        return cls(cls.config_class(**fields))


@dataclass(frozen=True)
class ImaginedRollout:
    """What `rollout` returns.

    Attributes:
        frames: (B, T, H, W, 3) uint8 imagined frames; frame t follows action t.
        actions: (B, T, A) float32 the actions applied.
        disagreement: (B, T) float of an ensemble (how far its members' frames differ), else None.
    """

    frames: torch.Tensor
    actions: torch.Tensor
    disagreement: torch.Tensor | None = None


def rollout(model: WorldModel, context: torch.Tensor, actions: torch.Tensor,
            generator: torch.Generator | None = None, states: torch.Tensor | None = None) -> ImaginedRollout:
    """Imagines fixed actions open-loop from real context frames, in one model call.

    Args:
        model: the world model.
        context: (B, C', H, W, 3) uint8 real frames; the last one is where the rollout starts.
        actions: (B, T, A) the actions (both copied to the model's device; the frames come back
            to the host).
        generator: passed to the model (stochastic backends draw from it).
        states: for a grounded model, (B, T, S) the state after each action (`check_states`).
    """
    device = module_device(model) if isinstance(model, torch.nn.Module) else torch.device("cpu")
    state = model.init_state(to_device(context, device), generator=generator)
    grounding = {} if states is None else {"states": to_device(states, device)}
    state, frames = model.step(state, to_device(actions, device), generator=generator, **grounding)
    disagreement = getattr(state, "disagreement", None)  # only ensembles know how far to trust a frame
    return ImaginedRollout(frames.cpu(), actions.float(), None if disagreement is None else disagreement.float().cpu())


BACKENDS = {"embedded": "gymnast.world_model.embedded:EmbeddedWorldModel",
            "flow": "gymnast.world_model.flow:FlowWorldModel",
            "ensemble": "gymnast.world_model.ensemble:EnsembleWorldModel"}
"""Backend name -> "module:Class", imported only when a checkpoint (or an ensemble directory) asks for it."""

PLUGIN_GROUP = "gymnast.world_models"
"""The entry-point group where installed packages register world models (``--wm plugin:NAME``)."""

REQUIRED = ("context_frames", "image_size", "action_dim", "init_state", "step")
"""What gymnast reads off any world model (the `WorldModel` protocol's members)."""

MULTI_VIEW = "gymnast.world_model.views:MultiViewWorldModel"
"""What wraps a backend saved with several cameras (its spec's ``cameras``); named, like the
backends, because it builds on this module."""

ENSEMBLE_FILE = "ensemble.json"
"""A directory holding this file is an ensemble of world-model runs (see `gymnast.world_model.ensemble`)."""


def load_world_model(run: str | Path, **overrides: Any) -> WorldModel:
    """The newest checkpoint of a world-model run (or a checkpoint directory), in eval mode; for a
    directory holding ``ensemble.json``, the ensemble of the runs it lists; or, for
    ``python:MODULE:FACTORY[@ARG]`` or ``plugin:NAME[@ARG]``, the user's own world model that
    factory returns (`gymnast.utils.plugins`; ``gymnast check-wm`` checks it keeps the contract).

    `overrides` replace fields of the saved model spec that do not change the weights (e.g. the
    embedded backend's ``reanchor_every``); an ensemble passes them to every member. A user's own
    model takes none.

    Raises:
        FileNotFoundError: no checkpoint there.
        ValueError: the checkpoint names an unknown backend, or a user's model lacks a part of the
            contract or was given overrides.
    """
    if is_plugin(run):
        return _plugin_world_model(str(run), overrides)

    def backend(name: Any) -> Any:
        if name not in BACKENDS:
            raise ValueError(f"{run}: model.backend is {name!r}; known backends: {sorted(BACKENDS)}")
        return import_named(BACKENDS[name])

    if (Path(run) / ENSEMBLE_FILE).is_file():
        return backend("ensemble").load(Path(run), **overrides).eval()
    cameras: list[str] = []

    def build(spec: dict) -> WorldModel:
        # A backend imagines one view; the cameras it learnt side by side wrap it once loaded.
        spec = {**spec, **overrides}
        cameras.extend(spec.pop("cameras", ()))
        return backend(spec.get("backend")).from_spec(spec)

    model = load_model(Path(run), build)
    return import_named(MULTI_VIEW)(model, cameras).eval() if len(cameras) > 1 else model


def _plugin_world_model(value: str, overrides: dict[str, Any]) -> WorldModel:
    """The world model a ``python:`` or ``plugin:`` factory returns, in eval mode where it is a module."""
    if overrides:
        raise ValueError(f"--wm {value}: {', '.join(sorted(overrides))} change(s) a saved gymnast world model; "
                         "your own world model takes its settings from its factory's argument (@ARG)")
    model = load_plugin(value, PLUGIN_GROUP)
    missing = missing_attributes(model, REQUIRED)
    if missing:
        raise ValueError(f"--wm {value}: the factory returned a {type(model).__name__}, which lacks {', '.join(missing)} "
                         "of the WorldModel contract (gymnast.world_model.base.WorldModel; `gymnast check-wm` checks it)")
    return model.eval() if isinstance(model, torch.nn.Module) else model


def placed(model: Any, device: torch.device) -> Any:
    """`model` on `device`: a module is moved there; a user's model that is not one places itself."""
    return model.to(device) if isinstance(model, torch.nn.Module) else model


@contextmanager
def offloaded(model: Any) -> Iterator[None]:
    """Lets a world model release its memory while gymnast trains: ``model.offload()`` on entry and
    ``model.onload()`` on exit (after an error too), for a model that has them; nothing otherwise."""
    offload, onload = getattr(model, "offload", None), getattr(model, "onload", None)
    if offload is None or onload is None:
        yield
        return
    offload()
    try:
        yield
    finally:
        onload()
