"""`gymnast check-wm`: does a world model keep the `WorldModel` contract gymnast relies on?

Legend: B batch, C context frames, K actions per `step` call, H/W image size (W: the V views side
by side), A action dimensions, S grounded state dimensions.

`check_world_model` calls the model on synthetic context frames and actions as gymnast does (the
imagined env, `rollout`) and returns every breach it finds, each with what to change. Frames are
compared in uint8 levels (0..255) by their mean absolute difference; `TOLERANCE` absorbs the last-bit
differences of floating-point kernels that run in another order (a batch of another size, a GPU).

A stochastic model's rows of one batch draw other noise than the same rows alone (the draws run
through one generator in batch order), so for it "a batch of one matches its row in a batch" is
held as: they differ by no more than two draws of different seeds differ (`STOCHASTIC_SLACK`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

from gymnast.utils.device import module_device
from gymnast.utils.plugins import Breach
from gymnast.world_model.base import REQUIRED, actions_per_frame, grounded_state_dim

TOLERANCE = 0.5
"""Mean absolute difference, in uint8 levels, below which two sets of frames count as the same."""
STOCHASTIC_SLACK = 3.0
"""How many times the seed-to-seed difference a stochastic model's batch rows may differ by."""


class _Stop(Exception):
    """A breach after which the check cannot go on (the model cannot be called as gymnast calls it)."""

    def __init__(self, breach: Breach) -> None:
        super().__init__(breach.message)
        self.breach = breach


def check_world_model(model: Any, batch: int = 2, actions: int = 5, seed: int = 0) -> list[Breach]:
    """Every breach of the `WorldModel` contract found by calling `model`; empty when it keeps it.

    Args:
        model: the world model (anything `gymnast.world_model.base.load_world_model` returns).
        batch: B of the batched calls (at least 2: rows of one batch are compared).
        actions: K per `step` call (raised to a multiple of the model's `actions_per_frame`).
        seed: of the synthetic frames and actions, and of the generators passed to the model.
    """
    if batch < 2:
        raise ValueError(f"check_world_model needs batch >= 2 to compare a batch's rows, got {batch}")
    missing = [name for name in REQUIRED if not hasattr(model, name)]
    if missing:
        return [Breach("attributes", f"the model lacks {', '.join(missing)}: a world model has context_frames, "
                                     "image_size and action_dim (ints) and init_state(context, generator) and "
                                     "step(state, actions, generator) (gymnast.world_model.base.WorldModel)")]
    sizes = {name: getattr(model, name) for name in ("context_frames", "image_size", "action_dim")}
    wrong = [f"{name}={value!r}" for name, value in sizes.items() if not isinstance(value, int) or value < 1]
    if wrong:
        return [Breach("attributes", f"{', '.join(wrong)}: context_frames, image_size and action_dim are positive ints")]
    breaches: list[Breach] = []
    try:
        _Checker(model, batch, actions, seed, breaches).run()
    except _Stop as stop:
        breaches.append(stop.breach)
    return breaches


class _Checker:
    """The calls of one check, on inputs made once."""

    def __init__(self, model: Any, batch: int, actions: int, seed: int, breaches: list[Breach]) -> None:
        self.model, self.breaches, self.seed = model, breaches, seed
        self.device = module_device(model) if isinstance(model, torch.nn.Module) else torch.device("cpu")
        per_frame = actions_per_frame(model)
        self.k = -(-actions // per_frame) * per_frame  # K, whole chunks of a frame-per-chunk model
        views, size = int(getattr(model, "views", 1)), model.image_size
        self.frame_shape = (size, views * size, 3)
        inputs = torch.Generator().manual_seed(seed)
        # Smooth scenes (a gradient and a few blocks), so a model that compresses frames sees something like a camera's.
        ramp = torch.linspace(0, 255, views * size)
        context = ramp.expand(batch, model.context_frames, size, -1).clone()
        context += torch.randint(0, 60, (batch, model.context_frames, 1, 1), generator=inputs)
        self.context = context[..., None].expand(-1, -1, -1, -1, 3).clamp(0, 255).to(torch.uint8).contiguous()
        low, high = (torch.tensor(bound, dtype=torch.float32) for bound in getattr(
            model, "action_range", ((-1.0,) * model.action_dim, (1.0,) * model.action_dim)))
        self.low, self.high = low, high
        self.actions = [self._actions(inputs, batch) for _ in range(2)]  # two continuations, (B, K, A) each
        dim = grounded_state_dim(model)
        self.states = torch.randn(batch, self.k, dim, generator=inputs) if dim else None  # (B, K, S)

    def _actions(self, inputs: torch.Generator, batch: int, width: int | None = None) -> torch.Tensor:
        width = width or self.model.action_dim
        unit = torch.rand(batch, self.k, width, generator=inputs)
        if width != self.model.action_dim:
            return unit * 2 - 1
        return self.low + unit * (self.high - self.low)

    def _generator(self, offset: int) -> torch.Generator:
        return torch.Generator(self.device).manual_seed(self.seed + offset)

    def _call(self, rule: str, what: str, advice: str, call: Callable[[], Any]) -> Any:
        try:
            return call()
        except Exception as error:  # the user's code may raise anything; the breach names it
            raise _Stop(Breach(rule, f"{what} raised {type(error).__name__}: {error}; {advice}")) from error

    def init(self, context: torch.Tensor, offset: int = 1) -> Any:
        return self._call("init_state", f"init_state(context {tuple(context.shape)} uint8)",
                          "init_state takes (B, C', H, W, 3) uint8 frames and the generator",
                          lambda: self.model.init_state(context.to(self.device), generator=self._generator(offset)))

    def step(self, state: Any, actions: torch.Tensor, rows: slice = slice(None), offset: int = 2) -> tuple[Any, torch.Tensor]:
        grounding = {} if self.states is None else {"states": self.states[rows].to(self.device)}
        result = self._call("step", f"step(state, actions {tuple(actions.shape)})",
                            "step takes (B, K, A) float actions and the generator (and a grounded model states (B, K, S))",
                            lambda: self.model.step(state, actions.to(self.device), generator=self._generator(offset),
                                                    **grounding))
        if not (isinstance(result, tuple) and len(result) == 2 and isinstance(result[1], torch.Tensor)):
            raise _Stop(Breach("step", f"step returned {type(result).__name__}; it returns (new state, frames tensor)"))
        return result

    def imagine(self, rows: slice = slice(None), continuation: int = 0, offset: int = 2) -> torch.Tensor:
        """(b, K, H, W, 3) frames of fresh rollouts of the context `rows`."""
        return self.step(self.init(self.context[rows]), self.actions[continuation][rows], rows, offset)[1].detach().cpu()

    def run(self) -> None:
        self.short_context()
        state, frames = self.first_step()
        self.frames(frames)
        self.disagreement(state)
        frames = frames.detach().cpu()
        if not self.reproducible(frames):
            return  # the checks below compare runs, which differ anyway
        self.state_in_place(frames)
        self.batch_rows(frames)
        self.offload_hooks(frames)

    def short_context(self) -> None:
        if self.model.context_frames < 2:
            return
        try:
            self.model.init_state(self.context[:, -1:].to(self.device), generator=self._generator(1))
        except Exception as error:
            self.breaches.append(Breach("short_context", f"init_state refused a context of 1 frame ({type(error).__name__}: "
                                        f"{error}) though fewer than context_frames={self.model.context_frames} are allowed "
                                        "(an episode starts from one real frame): repeat the first frame in front "
                                        "(gymnast.world_model.base.pad_context(context, context_frames))"))

    def first_step(self) -> tuple[Any, torch.Tensor]:
        """The first rollout's state and frames; a step that refuses the declared action width
        stops the check, naming the width it takes where another one works."""
        width = self.model.action_dim
        state = self.init(self.context)
        try:
            result = self.model.step(state, self.actions[0].to(self.device), generator=self._generator(2),
                                     **({} if self.states is None else {"states": self.states.to(self.device)}))
        except Exception as error:
            inputs = torch.Generator().manual_seed(self.seed)
            taken = [w for w in range(1, 33) if w != width and self._takes(self._actions(inputs, len(self.context), w))]
            took = f"; it takes {taken[0]}-wide actions: declare action_dim={taken[0]}" if taken else ""
            raise _Stop(Breach("action_width", f"step refused ({len(self.context)}, {self.k}, {width}) actions, the width "
                                               f"the model declares (action_dim={width}): {type(error).__name__}: {error}"
                                               f"{took}; a world model takes actions as wide as its action_dim")) from error
        if not (isinstance(result, tuple) and len(result) == 2 and isinstance(result[1], torch.Tensor)):
            raise _Stop(Breach("step", f"step returned {type(result).__name__}; it returns (new state, frames tensor)"))
        return result

    def _takes(self, actions: torch.Tensor) -> bool:
        try:
            self.model.step(self.model.init_state(self.context.to(self.device), generator=self._generator(1)),
                            actions.to(self.device), generator=self._generator(2),
                            **({} if self.states is None else {"states": self.states.to(self.device)}))
            return True
        except Exception:
            return False

    def frames(self, frames: torch.Tensor) -> None:
        expected = (len(self.context), self.k, *self.frame_shape)
        if frames.dtype != torch.uint8:
            self.breaches.append(Breach("frames_dtype", f"step returned {frames.dtype} frames; gymnast's frames are uint8 "
                                        "in 0..255, like a camera's: return (frames.clamp(0, 1) * 255).round()"
                                        ".to(torch.uint8) for frames in [0, 1]"))
        if tuple(frames.shape) == expected:
            return
        hint = ""
        if frames.ndim == 5 and frames.shape[2] == 3:
            hint = " (channels first? gymnast's frames are channels last: frames.permute(0, 1, 3, 4, 2))"
        elif frames.ndim == 5 and frames.shape[1] != self.k:
            hint = (f" ({frames.shape[1]} frames for {self.k} actions: return one per action; a model that imagines one "
                    "frame per chunk of N actions declares actions_per_frame = N and repeats the last imagined frame)")
        elif frames.ndim == 5 and tuple(frames.shape[2:]) != self.frame_shape:
            hint = (f" (frames of {frames.shape[2]}x{frames.shape[3]}: resize them to the declared image_size "
                    f"{self.model.image_size}, or declare the size the model makes)")
        raise _Stop(Breach("frames_shape", f"step returned frames of shape {tuple(frames.shape)}, expected {expected}: "
                                           f"(B, K, H, W, 3), one frame per action{hint}"))

    def disagreement(self, state: Any) -> None:
        values = getattr(state, "disagreement", None)
        expected = (len(self.context), self.k)
        if values is not None and (not isinstance(values, torch.Tensor) or tuple(values.shape) != expected):
            got = tuple(values.shape) if isinstance(values, torch.Tensor) else type(values).__name__
            self.breaches.append(Breach("disagreement", f"the state's disagreement is {got}, expected a {expected} tensor: "
                                        "how far to trust each frame of the last step (gymnast.world_model.ensemble)"))

    def reproducible(self, frames: torch.Tensor) -> bool:
        difference = _difference(frames, self.imagine())
        if difference <= TOLERANCE:
            return True
        self.breaches.append(Breach("generator", f"two rollouts from the same context and actions with generators "
                                    f"seeded alike differ (mean |difference| {difference:.2f} of 255): draw every "
                                    "random number from the generator passed to init_state and step (torch.randn("
                                    "..., generator=generator)), not from torch's global random state (the checks "
                                    "that compare runs, of the state and of a batch's rows, wait until it does)"))
        return False

    def state_in_place(self, fresh: torch.Tensor) -> None:
        """`fresh`: the first continuation from a fresh state (`first_step`'s frames)."""
        state = self.init(self.context)
        first = self.step(state, self.actions[0])[1].detach().cpu()
        second = self.step(state, self.actions[1])[1].detach().cpu()
        difference = max(_difference(first, fresh), _difference(second, self.imagine(continuation=1)))
        if difference > TOLERANCE:
            self.breaches.append(Breach("state_in_place", f"two continuations from one state differ from the same two "
                                        f"from fresh states (mean |difference| {difference:.2f} of 255): step changed the "
                                        "state it was given; gymnast branches rollouts from one state, so return a new "
                                        "state and leave the given one as it was (torch.cat or clone, not in-place "
                                        "writes or list.append)"))

    def batch_rows(self, together: torch.Tensor) -> None:
        """`together`: the batch's frames (`first_step`'s)."""
        alone = torch.cat([self.imagine(slice(b, b + 1)) for b in range(len(self.context))])
        difference = _difference(together, alone)
        if difference <= TOLERANCE:
            return
        spread = _difference(alone[:1], self.imagine(slice(0, 1), offset=3))  # another seed's draw
        if spread > TOLERANCE and difference <= STOCHASTIC_SLACK * spread:
            return
        self.breaches.append(Breach("batch", f"a batch's rows differ from the same inputs given as batches of one "
                                    f"(mean |difference| {difference:.2f} of 255; between two seeds {spread:.2f}): a row's "
                                    "frames must depend on its own context and actions only; look for reshapes or "
                                    "views that mix the batch with time or channels, or batch statistics (batch norm "
                                    "in training mode)"))

    def offload_hooks(self, frames: torch.Tensor) -> None:
        hooks = [name for name in ("offload", "onload") if callable(getattr(self.model, name, None))]
        if not hooks:
            return
        if len(hooks) == 1:
            other = "onload" if hooks == ["offload"] else "offload"
            self.breaches.append(Breach("offload", f"the model has {hooks[0]}() but no {other}(): gymnast calls offload() "
                                        "before its training steps and onload() after them, so it needs both"))
            return
        self._call("offload", "offload()", "it releases the model's memory until onload()", self.model.offload)
        self._call("offload", "onload()", "it brings the model back after offload()", self.model.onload)
        difference = _difference(frames, self.imagine())
        if difference > TOLERANCE:
            self.breaches.append(Breach("offload", f"after offload() and onload() the model imagines other frames (mean "
                                        f"|difference| {difference:.2f} of 255): onload() must restore the model as it was"))


def _difference(a: torch.Tensor, b: torch.Tensor) -> float:
    """Mean absolute difference in uint8 levels (float frames in [0, 1] are scaled to them)."""
    if a.shape != b.shape:
        return float("inf")
    scale = 255.0 if a.is_floating_point() else 1.0
    return (a.float() - b.float()).abs().mean().item() * scale
