"""Imagined environments: Gymnasium envs whose frames come from a world model, not a simulator.

Legend: B batch (parallel rollouts), C start frames, K actions per chunk (one env step), T
actions taken so far, H/W image size, A action dimensions.

The RL loop drives `ImaginedEnv` like `MetaWorldEnv` (the same ``"image"`` (H, W, 3) uint8 and
``info["instruction"]``; no ``"state"``, which a video model does not imagine), so it never knows
where the frames come from. What differs, and why:

- An episode starts from a *real* camera frame and instruction (a `gymnast.envs.starts.Start`, or
  the reset options): a world model can continue a scene but not invent a faithful one.
- One step is one action chunk (K, A), imagined as K frames in one model call: all are in
  ``info["frames"]``, and the whole video in `video()`.
- ``reward`` is always 0.0 and ``terminated`` always False: the world model cannot tell success.
  Rewards are computed afterwards by a judge (`gymnast.reward`) on the whole video, which also
  decides success. ``truncated`` means the horizon of T actions was reached; the last chunk is cut
  so that exactly ``horizon`` frames are imagined.
- `BatchedImaginedEnv` steps B rollouts in one world-model call (where the speed is). It never
  autoresets: after truncation `step` raises until `reset`, because new rollouts need new real
  start frames, which only the RL loop has.
- A batched env given a ``robot_state`` (`gymnast.world_model.robot_state.ImaginedRobotState`:
  a state model stepped under the same actions from each start's recorded state) also reports
  ``obs["state"]`` (B, D), the imagined robot state a policy that reads one is given.
- A grounded world model (``state_dim`` S > 0) renders every frame at a state: the batched env
  then needs a ``robot_state``, steps it first and gives the model its whole state after each
  action. ``obs["state"]`` is reported only where the robot state has D > 0 (a policy reads it).
- A world model that says how much to trust each frame (an ensemble's `disagreement`, (B, k) per
  step) has it reported in ``info["disagreement"]``; a single model reports none. The batched env
  can stop a rollout where it exceeds a threshold (``stop_above``): the rollout is truncated
  before the first such frame, which it never shows (see `BatchedImaginedEnv`).

Observations and infos are fresh arrays on every call (check_env insists, and users keep them).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch
from gymnasium.spaces import Box, Dict
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from gymnast.envs.metaworld import CONTROL_FPS
from gymnast.envs.starts import Start


class WorldModel(Protocol):
    """The part of the `gymnast.world_model.base.WorldModel` contract these envs call.

    Stated here rather than imported, because envs sit below world models: every world model
    satisfies it structurally, and the contract's meaning is documented there.
    """

    image_size: int  # H = W of one camera's view
    action_dim: int  # A
    # A model of several cameras also has `views` (V): its frames are (H, V*W, 3), side by side.

    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> Any: ...

    def step(self, state: Any, actions: torch.Tensor, generator: torch.Generator | None = None) -> tuple[Any, torch.Tensor]: ...


def frame_shape(model: WorldModel) -> tuple[int, int, int]:
    """(H, V*W, 3): the frames a world model takes and imagines, its V cameras' views side by side."""
    return model.image_size, getattr(model, "views", 1) * model.image_size, 3


def _spaces(model: WorldModel, chunk_size: int) -> tuple[Dict, Box]:
    """The observation space and the action space: each dimension spans the model's
    ``action_range`` (the range its training data's actions spanned), or [-1, 1], Meta-World's."""
    observation = Dict({"image": Box(0, 255, frame_shape(model), np.uint8)})
    low, high = getattr(model, "action_range", ((-1.0,) * model.action_dim, (1.0,) * model.action_dim))
    shape = (chunk_size, model.action_dim)
    return observation, Box(np.broadcast_to(np.float32(low), shape), np.broadcast_to(np.float32(high), shape), shape, np.float32)


def _check_frames(frames: Any, shape: tuple[int, int, int], batch: int | None = None) -> np.ndarray:
    """Real start frames of `shape` (`frame_shape`) as a (B, C, H, W, 3) uint8 copy (B = 1 without
    `batch`), or ValueError."""
    lead = "" if batch is None else f"{batch}, "
    height, width, _ = shape
    expected = f"({lead}{height}, {width}, 3) or ({lead}C, {height}, {width}, 3) uint8"
    frames = np.asarray(frames)
    given = frames.shape
    frames = frames if batch else frames[None]  # (B, [C,] H, W, 3)
    frames = frames[:, None] if frames.ndim == 4 else frames  # (B, C, H, W, 3)
    ok = frames.ndim == 5 and frames.shape[0] == (batch or 1) and frames.shape[1] >= 1
    if not ok or frames.shape[2:] != tuple(shape) or frames.dtype != np.uint8:
        views = shape[1] // shape[0]
        cameras = f" (the world model's {views} cameras side by side)" if views > 1 else ""
        raise ValueError(f"start frames must be {expected}{cameras}, got {given} {frames.dtype}")
    return frames.copy()


def _check_actions(actions: Any, space: Box, names: str) -> np.ndarray:
    """Actions as a float32 array clipped to `space`, or ValueError naming the shapes."""
    actions = np.asarray(actions, dtype=np.float32)
    if actions.shape != space.shape:
        raise ValueError(f"actions must have shape {space.shape} {names}, got {actions.shape}")
    if not np.isfinite(actions).all():
        raise ValueError("actions must be finite")
    return np.clip(actions, space.low, space.high)


def hold_after_end(frames: np.ndarray, executed: np.ndarray, before: np.ndarray) -> None:
    """Holds, in place, each rollout's last frame over the (B, k, H, W, 3) `frames` of a step after its
    (B,) `executed` actions: the frame of its last action, or `before` (B, H, W, 3), the frame
    it showed before the step, where it executed none. An ended rollout shows its last frame from then
    on, as a finished simulator episode does."""
    for b in np.flatnonzero(executed < frames.shape[1]):
        frames[b, executed[b]:] = frames[b, executed[b] - 1] if executed[b] else before[b]


class HostCopier:
    """Brings frames to the host as fresh arrays (the env keeps every step's frames as the video).

    From a GPU through one page-locked buffer kept for the next step, then a parallel copy into
    ordinary memory: on an H100 a step's frames at batch 4096 (566 MB) came over in 0.11 s so, in
    0.50 s through freshly page-locked memory each step (allocating it is the cost) and in 0.43 s
    through pageable memory (benchmarks/results/gpu_host_copy.json)."""

    def __init__(self) -> None:
        self._staging: torch.Tensor | None = None

    def __call__(self, frames: torch.Tensor) -> np.ndarray:
        if frames.device.type != "cuda":
            return frames.cpu().numpy()
        if self._staging is None or self._staging.shape != frames.shape or self._staging.dtype != frames.dtype:
            self._staging = torch.empty(frames.shape, dtype=frames.dtype, pin_memory=True)
        self._staging.copy_(frames)  # synchronous: the buffer holds this step's frames when it returns
        # A fresh array each step: the stored video keeps every step's frames, the buffer only the last.
        return torch.empty(frames.shape, dtype=frames.dtype).copy_(self._staging).numpy()


class _Imagination:
    """What both envs share: B rollouts of one model, a step counter and the imagined video."""

    def __init__(self, model: WorldModel, chunk_size: int, horizon: int) -> None:
        if chunk_size < 1 or horizon < 1:
            raise ValueError(f"need chunk_size >= 1 and horizon >= 1, got {chunk_size}, {horizon}")
        # A model of one frame per N actions (the contract's `actions_per_frame`) shows a chunk that
        # ends mid-way through its N the frame before it: the policy would act on a stale frame.
        per_frame = int(getattr(model, "actions_per_frame", 1))
        if chunk_size % per_frame:
            raise ValueError(f"the world model imagines one frame per {per_frame} actions; a policy chunk of {chunk_size} "
                             f"actions would read a frame from before its last actions (use a chunk that is a multiple "
                             f"of {per_frame}, or a world model of one frame per action)")
        self.model, self.horizon = model, horizon
        parameters = getattr(model, "parameters", None)  # a module's device; modules store none
        self.device = next(parameters(), torch.zeros(0)).device if parameters else torch.device("cpu")
        self.steps, self.state = 0, None
        self.chunks: list[np.ndarray] = []  # (B, k, H, W, 3) each; the first is the start frame
        self.disagreement: np.ndarray | None = None  # (B, k) of the last step, when the model says
        self._to_host = HostCopier()

    def start(self, context: np.ndarray, seed: int) -> np.ndarray:
        """Starts from (B, C, H, W, 3) real frames; returns the (B, H, W, 3) start frame."""
        self.generator = torch.Generator(self.device).manual_seed(seed)  # for stochastic backends
        self.state = self.model.init_state(torch.from_numpy(context).to(self.device), generator=self.generator)
        self.steps, self.chunks = 0, [context[:, -1:]]
        return context[:, -1].copy()

    def restart(self, context: np.ndarray) -> None:
        """Continues every rollout from (B, C, H, W, 3) real frames instead of its own last ones: the
        model's state starts again there, the step count goes on, and the video's newest frame
        becomes the real one."""
        if self.state is None:
            raise RuntimeError("call reset() with real start frames before restarting from other ones")
        self.state = self.model.init_state(torch.from_numpy(context).to(self.device), generator=self.generator)
        newest = self.chunks[-1].copy()  # the model's own frames may share memory with its state
        newest[:, -1] = context[:, -1]
        self.chunks[-1] = newest

    def remaining(self, actions: np.ndarray) -> np.ndarray:
        """(B, K, A) actions cut at the horizon: the (B, k, A) that `step` imagines."""
        if self.state is None:
            raise RuntimeError("call reset() with real start frames before step()")
        if self.steps >= self.horizon:
            raise RuntimeError(f"the episode was truncated at its horizon of {self.horizon} actions; call reset()")
        return actions[:, : self.horizon - self.steps]

    def step(self, actions: np.ndarray, states: torch.Tensor | None = None) -> tuple[np.ndarray, bool]:
        """Applies (B, K, A) actions, cut at the horizon (a grounded model's frames at the (B, k, S)
        `states`); returns (B, k, H, W, 3) frames, truncated."""
        actions = self.remaining(actions)  # (B, k, A)
        tensor = torch.from_numpy(actions).to(self.device)
        grounding = {} if states is None else {"states": states.to(self.device)}
        self.state, frames = self.model.step(self.state, tensor, generator=self.generator, **grounding)
        frames = self._to_host(frames)  # (B, k, H, W, 3) uint8
        disagreement = getattr(self.state, "disagreement", None)  # only ensembles know how far to trust a frame
        self.disagreement = None if disagreement is None else disagreement.float().cpu().numpy()  # (B, k)
        self.steps += actions.shape[1]
        self.chunks.append(frames)
        return frames, self.steps >= self.horizon

    def video(self) -> np.ndarray:
        if self.state is None:
            raise RuntimeError("call reset() before video()")
        return np.concatenate(self.chunks, axis=1)  # (B, T + 1, H, W, 3)


class ImaginedEnv(gym.Env):
    """One imagined rollout as a Gymnasium environment (see the module docstring).

    Observation: ``{"image": (H, W, 3) uint8}``. Action: (K, A) float32 in [-1, 1], one chunk.
    ``info``: ``instruction``, ``step`` (actions taken) and, after `step`, ``frames`` (k, H, W, 3)
    uint8, every frame imagined in that step, and ``disagreement`` (k,) float32 when the world model
    reports one (an ensemble).

    Args:
        model: any `WorldModel`.
        starts: real start states that `reset` without options draws from (with `np_random`); it
            reads their frames and instruction.
        chunk_size: K, actions per step.
        horizon: actions per episode; the episode is truncated when they are taken.
        render_mode: None or ``rgb_array`` (the latest frame).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": CONTROL_FPS}

    def __init__(
        self,
        model: WorldModel,
        starts: Sequence[Start] = (),
        chunk_size: int = 5,
        horizon: int = 150,
        render_mode: str | None = None,
    ) -> None:
        self._sim = _Imagination(model, chunk_size, horizon)
        for start in starts:
            _check_frames(start.frames, frame_shape(model))  # fail at construction, not mid-training
        self.starts = tuple(starts)
        self.render_mode = render_mode
        # render() gives one frame per step, and a step spans `chunk_size` real-time actions.
        self.metadata = {**self.metadata, "render_fps": CONTROL_FPS / chunk_size}
        self.observation_space, self.action_space = _spaces(model, chunk_size)
        self._instruction = ""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts from ``options`` ``{"frames": ([C,] H, W, 3) uint8, "instruction": str}``, or else
        from one of `starts`; ValueError without a start, or for frames of the wrong shape or dtype."""
        super().reset(seed=seed)
        if options:
            if "frames" not in options or not isinstance(options.get("instruction"), str):
                raise ValueError('reset options need both "frames" and an "instruction" string')
            frames, instruction = options["frames"], options["instruction"]
        elif self.starts:
            start = self.starts[int(self.np_random.integers(len(self.starts)))]
            frames, instruction = start.frames, start.instruction
        else:
            raise ValueError(
                "the imagined env needs a real start frame and instruction: pass "
                'reset(options={"frames": ..., "instruction": ...}) or build it with starts=[Start(...)]'
            )
        context = _check_frames(frames, frame_shape(self._sim.model))
        self._instruction = instruction
        frame = self._sim.start(context, seed=int(self.np_random.integers(2**63)))[0]
        return {"image": frame}, {"instruction": self._instruction, "step": 0}

    def step(self, action):
        """Imagines one chunk; reward 0.0 and terminated False always (a judge scores the video)."""
        actions = _check_actions(action, self.action_space, "(chunk_size, action_dim)")
        frames, truncated = self._sim.step(actions[None])
        frames = frames[0]  # (k, H, W, 3)
        info = {"instruction": self._instruction, "step": self._sim.steps, "frames": frames.copy()}
        if self._sim.disagreement is not None:
            info["disagreement"] = self._sim.disagreement[0].copy()
        return {"image": frames[-1].copy()}, 0.0, False, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self._sim.state is None:
            raise RuntimeError("call reset() before render()")
        return self._sim.chunks[-1][0, -1].copy()

    def video(self) -> np.ndarray:
        """(T + 1, H, W, 3) uint8: the real start frame, then every imagined frame so far."""
        return self._sim.video()[0]


class RobotState(Protocol):
    """The robot's state beside the imagined frames (`gymnast.world_model.robot_state.ImaginedRobotState`)."""

    dim: int
    """D, the robot state's dimensions."""

    def start(self, states: np.ndarray, last_actions: np.ndarray, instructions: Sequence[str]) -> np.ndarray: ...

    def imagine(self, actions: np.ndarray) -> torch.Tensor: ...

    def robot(self) -> np.ndarray: ...


def grounded_state_dim(model: Any) -> int:
    """S of a world model that renders every frame at a state; 0 for one that is not grounded (the
    contract's `gymnast.world_model.base.grounded_state_dim`, restated here below world models)."""
    return int(getattr(model, "state_dim", 0))


class BatchedImaginedEnv(VectorEnv):
    """B imagined rollouts stepped together in one world-model call; no autoreset.

    Observation: ``{"image": (B, H, W, 3) uint8}``. Action: (B, K, A) float32 in [-1, 1].
    ``infos``: ``instruction`` (B,) str, ``step`` (B,) int and, after `step`, ``frames``
    (B, k, H, W, 3) uint8 (the stored video's own memory: copy it before changing it) and, when the
    world model reports one, ``disagreement`` (B, k) float32. All rollouts start together, and are truncated together at the horizon.
    The arguments are `ImaginedEnv`'s, with ``num_envs`` B instead of starts (reset takes them), and:

    Args:
        stop_above: if given, a rollout ends (truncated) before its first frame whose disagreement
            exceeds it: that frame is not trusted, so the rollout executes only the actions before
            it and shows its last trusted frame from then on (in observations, ``frames`` and
            `video`), as a finished simulator episode does. ``infos`` then also hold ``executed``
            (B,) actions each rollout executed in the step and ``stopped`` (B,) bool so far.
            Needs a world model that reports disagreement (RuntimeError at `step` otherwise).
        robot_state: if given, observations also hold ``"state"`` (B, D) float32, the robot state
            it imagines under the same actions (none where D is 0); reset then needs each start's
            recorded state (``options["states"]``) and the actions that led there
            (``options["prefixes"]``). A grounded world model needs one: its frames are rendered at
            the states it imagines.

    Raises:
        ValueError: a grounded world model without a robot state.
    """

    metadata = {"autoreset_mode": AutoresetMode.DISABLED, "render_modes": [], "render_fps": CONTROL_FPS}

    def __init__(self, model: WorldModel, num_envs: int, chunk_size: int = 5, horizon: int = 150,
                 stop_above: float | None = None, robot_state: RobotState | None = None) -> None:
        self._sim = _Imagination(model, chunk_size, horizon)
        self.num_envs, self.stop_above, self.robot_state = num_envs, stop_above, robot_state
        self.grounded = grounded_state_dim(model) > 0
        if self.grounded and robot_state is None:
            raise ValueError(f"the world model renders every frame at a {grounded_state_dim(model)}-d state: the imagined "
                             "env needs a robot_state (a state model, --robot-state RUN) that imagines it")
        self._stopped = np.zeros(num_envs, dtype=bool)
        self.single_observation_space, self.single_action_space = _spaces(model, chunk_size)
        if self._reports_state:
            self.single_observation_space = Dict({**self.single_observation_space.spaces, "state": Box(
                -np.inf, np.inf, (robot_state.dim,), np.float32)})
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._instructions = np.array([""] * num_envs, dtype=object)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts all B rollouts from ``options`` ``{"frames": (B, [C,] H, W, 3) uint8, "instructions":
        B strings}``; ValueError when they are missing or do not fit."""
        super().reset(seed=seed)
        options = options or {}
        if "frames" not in options or "instructions" not in options:
            shapes = f'{{"frames": ({self.num_envs}, [C,] H, W, 3) uint8, "instructions": {self.num_envs} strings}}'
            raise ValueError(f"the imagined env needs real start frames and instructions: reset(options={shapes})")
        context = _check_frames(options["frames"], frame_shape(self._sim.model), batch=self.num_envs)
        instructions = list(options["instructions"])
        if len(instructions) != self.num_envs or not all(isinstance(i, str) for i in instructions):
            raise ValueError(f"instructions must be {self.num_envs} strings, got {instructions!r}")
        self._instructions = np.array(instructions, dtype=object)
        self._stopped = np.zeros(self.num_envs, dtype=bool)
        frames = self._sim.start(context, seed=int(self.np_random.integers(2**63)))
        obs = {"image": frames}
        if self.robot_state is not None:
            state = self.robot_state.start(*self._recorded_states(options), instructions)
            if self._reports_state:
                obs["state"] = state
        return obs, self._info()

    @property
    def _reports_state(self) -> bool:
        """Whether observations hold the robot's state (a policy reads it)."""
        return self.robot_state is not None and self.robot_state.dim > 0

    def _recorded_states(self, options: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """(B, S) each start's recorded state and (B, A) the last action that led there (zeros at
        a first frame), from reset ``options``; ValueError naming what is missing."""
        states, prefixes = options.get("states"), options.get("prefixes")
        if states is None or len(states) != self.num_envs or any(np.size(state) == 0 for state in states):
            raise ValueError(f"an imagined robot state starts from each start's recorded state: reset(options="
                             f"{{\"states\": {self.num_envs} (S,) arrays, ...}}) from starts that carry their state")
        action_dim = self.single_action_space.shape[-1]
        last = [np.asarray(p, np.float32)[-1] if p is not None and len(p) else np.zeros(action_dim, np.float32)
                for p in (prefixes if prefixes is not None else [None] * self.num_envs)]
        return np.stack([np.asarray(state, np.float32) for state in states]), np.stack(last)

    def step(self, actions):
        """Imagines one chunk per rollout; rewards 0 and terminations False (a judge scores videos)."""
        actions = _check_actions(actions, self.action_space, "(num_envs, chunk_size, action_dim)")
        # A grounded model's frames are drawn where the state model says things are after each action.
        states = self.robot_state.imagine(self._sim.remaining(actions)) if self.grounded else None
        frames, truncated = self._sim.step(actions, states)
        ended, extra = np.full(self.num_envs, truncated), {}
        if self._sim.disagreement is not None:
            extra["disagreement"] = self._sim.disagreement.copy()
        if self.stop_above is not None:
            frames, executed = self._stop(frames)
            extra |= {"executed": executed, "stopped": self._stopped.copy()}
            ended |= self._stopped
        # The stored video's own chunk, not a copy (a copy of batch 4096's step took 0.44 s, 20x the
        # model on a GPU): readers copy what they change, as the RL rollout's concatenation does.
        infos = {**self._info(), "frames": frames, **extra}
        zeros = np.zeros(self.num_envs)
        obs = {"image": frames[:, -1].copy()}
        if self.robot_state is not None and not self.grounded:
            self.robot_state.imagine(actions[:, : frames.shape[1]])  # the actions imagined
        if self._reports_state:
            obs["state"] = self.robot_state.robot()
        return obs, zeros, zeros.astype(bool), ended, infos

    def restart(self, frames: np.ndarray) -> np.ndarray:
        """Continues every rollout from real frames, (B, [C,] H, W, 3) uint8 (the world each rollout's
        actions reached), instead of the ones it imagined; returns the (B, H, W, 3) frames now
        shown. The step count and the video go on, the video's newest frame the real one.

        Raises:
            ValueError: frames of the wrong shape or dtype, or a robot state beside the frames
                (which would have to restart from the real state as well).
        """
        if self.robot_state is not None:
            raise ValueError("an imagined env with a robot state cannot restart from real frames alone: "
                             "its state would go on from the imagined one")
        context = _check_frames(frames, frame_shape(self._sim.model), batch=self.num_envs)
        self._sim.restart(context)
        return context[:, -1].copy()

    def _stop(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stops rollouts before their first frame over `stop_above`; returns the step's (B, k, H, W, 3)
        frames with a stopped rollout's last trusted frame repeating (the stored video too, so it
        agrees), and (B,) actions executed."""
        if self._sim.disagreement is None:
            raise RuntimeError("stop_above needs a world model that reports disagreement (an ensemble)")
        count = frames.shape[1]
        over = self._sim.disagreement > self.stop_above  # (B, k)
        trusted = np.where(over.any(axis=1), over.argmax(axis=1), count)  # (B,) frames before the first over
        executed = np.where(self._stopped, 0, trusted)
        before = self._sim.chunks[-2][:, -1]  # (B, H, W, 3) the last frame of the previous step
        frames = frames.copy()  # the model's own frames may share memory with its state
        hold_after_end(frames, executed, before)
        self._sim.chunks[-1] = frames
        self._stopped |= executed < count
        return frames, executed

    def video(self) -> np.ndarray:
        """(B, T + 1, H, W, 3) uint8: the real start frames, then every imagined frame so far."""
        return self._sim.video()

    def _info(self) -> dict[str, Any]:
        return {"instruction": self._instructions.copy(), "step": np.full(self.num_envs, self._sim.steps)}
