"""B Meta-World episodes stepped one action chunk at a time: RL in the real world or the simulator.

Legend: B batch (parallel episodes), K actions per chunk (one env step), A action dimensions,
H/W image size.

Gymnasium's own vector envs do not fit RL rollouts: they autoreset a sub-env when it ends (or
assert that none ends alone), while GRPO rollouts must end independently, at success or at the
horizon, and must start from chosen (task, seed) pairs so that a group shares one initial state.
`SimVectorEnv` keeps `BatchedImaginedEnv`'s contract (one step is a (B, K, A) chunk, its frames
in ``infos["frames"]``, no autoreset) so the RL loop drives either without knowing which; unlike
the imagined env it knows rewards and success, so each episode ends on its own and then stays
frozen: never stepped again, its final frame repeated, NaN rewards, ``executed`` 0.

Each episode is stepped by the rollout engine's `gymnast.envs.engine.play_chunk`, the code that
plays `gymnast eval`'s and `gymnast collect`'s episodes, so success means the same in all of them.
MuJoCo stepping and rendering are single-threaded, so ``workers > 1`` splits the B episodes into
contiguous slices over worker processes, spawned here or Ray actors (`gymnast.envs.workers`); the
episodes run the same code in either case, so the results are identical.

Starting a worker (importing torch, MuJoCo and Meta-World, building its first scenes) costs
seconds, and an experiment builds dozens of short-lived envs (every arm's training, evaluations,
replays). Inside ``with shared_simulator_processes():`` a closed env's workers wait for the next
env of the same settings instead of stopping, and are stopped at the end of the block. An env
holds its workers alone while it is open, and workers that failed a call are never passed on.
"""

from __future__ import annotations

import contextlib
import itertools
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any, ClassVar, Self

import numpy as np
from gymnasium.spaces import Box, Dict
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from gymnast.config import EnvConfig
from gymnast.envs.engine import EpisodeRun, play_chunk, start_episode
from gymnast.envs.gap import get_gap
from gymnast.envs.instructions import SPLITS
from gymnast.envs.metaworld import ACTION_DIM, CONTROL_FPS, ENV_STATE_DIM, STATE_DIM, MetaWorldEnv
from gymnast.envs.tasks import check_task
from gymnast.envs.workers import Workers, parse_runner
from gymnast.utils.memory import release_freed_memory


class _Episodes:
    """A contiguous slice of the B episodes, run in this process (the parent's or a worker's).

    Environments are cached per (task, n), n counting the slice's earlier episodes of that task,
    because building a Meta-World scene costs far more than resetting one. When resets draw ever
    new mixes of tasks the cache would keep growing (an environment holds tens of MB), so past
    twice the slice's size the environments the current reset does not use are closed, and their
    memory is given back to the operating system (`gymnast.utils.memory`).
    """

    def __init__(self, config: EnvConfig, gap: str, instruction_split: str) -> None:
        self._args = {"config": config, "gap": gap, "instruction_split": instruction_split}
        self._envs: dict[tuple[str, int], MetaWorldEnv] = {}
        self._episodes: list[EpisodeRun] = []
        self._every_frame = True

    def reset(self, tasks: list[str], seeds: list[int], instructions: list[str | None],
              prefixes: list[np.ndarray | None] | None = None, every_frame: bool = True) -> dict[str, np.ndarray]:
        counts: Counter[str] = Counter()
        self._episodes, self._every_frame = [], every_frame
        for task, seed, instruction, prefix in zip(tasks, seeds, instructions, prefixes or [None] * len(tasks)):
            key = (task, counts[task])
            counts[task] += 1
            if key not in self._envs:
                self._envs[key] = MetaWorldEnv(task, **self._args)
            # The full simulator state after every action: a reward model of states reads the real ones.
            self._episodes.append(start_episode(self._envs[key], seed, instruction, record=("env_states",),
                                                prefix=prefix))
        if len(self._envs) > 2 * len(self._episodes):
            used = {id(e.env) for e in self._episodes}
            for key in [key for key, env in self._envs.items() if id(env) not in used]:
                self._envs.pop(key).close()
            release_freed_memory()  # else the closed scenes stay in the process's resident memory
        frames = np.stack([e.obs["image"] for e in self._episodes])  # (b, H, W, 3)
        instructions = np.array([e.instruction for e in self._episodes], dtype=object)
        prefix_steps = np.array([e.prefix_steps for e in self._episodes], np.int64)
        return {"image": frames, "state": self._states(), "instruction": instructions, "prefix_steps": prefix_steps,
                **self._status()}

    def step(self, actions: np.ndarray) -> dict[str, np.ndarray]:
        """Runs each episode's (K, A) actions open-loop until the chunk or the episode ends."""
        b, k = actions.shape[:2]
        config = self._args["config"]
        frames = np.empty((b, k, config.image_size, len(config.cameras) * config.image_size, 3), np.uint8)
        rewards = np.full((b, k), np.nan)
        env_states = np.full((b, k, ENV_STATE_DIM), np.nan, np.float32)
        executed = np.zeros(b, np.int64)
        for i, episode in enumerate(self._episodes):
            played = play_chunk(episode, actions[i], self._every_frame)
            executed[i] = len(played)
            rewards[i, : len(played)] = [reward for _, reward in played]
            if played:
                env_states[i, : len(played)] = episode.env_states[-len(played):]
            # Each step's frame, then the final one after an episode's end; without every_frame, all of
            # them the chunk's last (the others were not rendered).
            shown = len(played) if self._every_frame else 0
            for j, (obs, _) in enumerate(played[:shown]):
                frames[i, j] = obs["image"]
            frames[i, shown:] = episode.obs["image"]
        return {"frames": frames, "state": self._states(), "rewards": rewards, "executed": executed,
                "env_states": env_states, **self._status()}

    def _states(self) -> np.ndarray:
        """(b, D) float32 each episode's robot state now (hand position and gripper)."""
        return np.stack([e.obs["state"] for e in self._episodes]).astype(np.float32)

    def _status(self) -> dict[str, np.ndarray]:
        names = {"step": ("steps", np.int64), "success": ("success", bool), "terminated": ("terminated", bool),
                 "truncated": ("truncated", bool)}
        return {name: np.array([getattr(e, field) for e in self._episodes], dtype) for name, (field, dtype) in names.items()}

    def scenes(self) -> int:
        """How many scenes this slice keeps built."""
        return len(self._envs)

    def close(self) -> None:
        """Closes every scene and gives their memory back; a later `reset` builds them again."""
        for env in self._envs.values():
            env.close()
        self._envs.clear()
        self._episodes = []
        release_freed_memory()


class SimVectorEnv(VectorEnv):
    """B Meta-World episodes (of any tasks) stepped one action chunk at a time; no autoreset.

    Observation: ``{"image": (B, H, W, 3) uint8, "state": (B, D) float32}``, W the views side by
    side, D the robot state's dimensions (hand xyz and gripper). Action: (B, K, A) float32 in [-1, 1].
    ``rewards`` (B,) are the dense rewards summed over the actions executed in the chunk;
    ``terminated`` (B,) means success, ``truncated`` (B,) the horizon; whichever ended an episode
    stays True. ``infos``: ``instruction`` (B,) str, ``task`` (B,) str, ``seed`` (B,) int,
    ``prefix_steps`` (B,) int real actions replayed to restore each start (0 for a first frame),
    ``step`` (B,) int actions taken so far (from the start), ``success`` (B,) bool succeeded at any step so far and,
    after `step`, ``frames`` (B, K, H, W, 3) uint8, ``rewards`` (B, K) float (NaN where no action
    was executed), ``env_states`` (B, K, 39) float32 Meta-World's full state after each action (NaN
    where none was executed) and ``executed`` (B,) int actions executed in the chunk.

    Args:
        num_envs: B, episodes stepped together.
        chunk_size: K, actions per step.
        config: image size, horizon and camera (and whether success ends an episode).
        gap: ``none`` (the real world), or a simulator gap such as ``mild``.
        instruction_split: ``train`` or ``heldout`` paraphrases of the default instructions.
        workers: processes to step the episodes in; 1 runs them in this process.
        runner: where the processes run: local, ray or ray:ADDRESS (`gymnast.envs.workers.parse_runner`).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "autoreset_mode": AutoresetMode.DISABLED, "render_modes": [], "render_fps": CONTROL_FPS
    }

    def __init__(self, num_envs: int, chunk_size: int = 5, config: EnvConfig | None = None, gap: str = "none",
                 instruction_split: str = "train", workers: int = 1, runner: str = "local") -> None:
        if num_envs < 1 or chunk_size < 1 or workers < 1:
            raise ValueError(f"need num_envs, chunk_size and workers >= 1, got {num_envs}, {chunk_size}, {workers}")
        if instruction_split not in SPLITS:
            raise ValueError(f"instruction_split must be one of {SPLITS}, got {instruction_split!r}")
        get_gap(gap)  # fail here, with its own message, rather than inside a worker
        parse_runner(runner)
        self.config = config or EnvConfig()
        self.num_envs = num_envs
        size = self.config.image_size
        width = len(self.config.cameras) * size  # the views side by side (gymnast.envs.metaworld)
        self.single_observation_space = Dict({"image": Box(0, 255, (size, width, 3), np.uint8),
                                              "state": Box(-np.inf, np.inf, (STATE_DIM,), np.float32)})
        self.single_action_space = Box(-1.0, 1.0, (chunk_size, ACTION_DIM), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        bounds = np.linspace(0, num_envs, min(workers, num_envs) + 1).astype(int)
        self._slices = [slice(a, b) for a, b in itertools.pairwise(bounds)]  # contiguous
        self._info: dict[str, np.ndarray] | None = None
        self._local: _Episodes | None = None
        self.workers: Workers | None = None
        self._pool_key = (runner, len(self._slices), self.config, gap, instruction_split)
        self._healthy = True  # until a worker call fails
        if len(self._slices) == 1:
            self._local = _Episodes(self.config, gap, instruction_split)
        else:
            self.workers = _shared.lease(self._pool_key) or Workers(runner, len(self._slices), _Episodes,
                                                                    (self.config, gap, instruction_split))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts episode i as ``MetaWorldEnv(tasks[i]).reset(seed=seeds[i])`` would.

        Args:
            seed: seeds `np_random` only; the episodes' initial states come from ``options``.
            options: ``{"tasks": B task names, "seeds": B non-negative ints, "instructions": B
                strings, "prefixes": B (T0, A) action arrays}``; instructions optional (default:
                each episode's own), prefixes optional (default: start at the first frame; else
                each episode starts at the keyframe its prefix reaches from the scene, restored
                exactly by replaying it). Other keys are ignored, so one dict can describe a real
                start for this env and the imagined one. ``"every_frame": False`` renders only
                each chunk's last frame (what the policy reads; an evaluation needs no more): the
                chunk's other ``frames`` repeat it.

        Raises:
            ValueError: naming the field that is missing or has the wrong length or type.
        """
        super().reset(seed=seed)
        self._info = None  # until every slice has reset
        options = options or {}
        tasks = self._field(options, "tasks", "task names", lambda t: isinstance(t, str))
        for task in tasks:
            check_task(task)
        seeds = self._field(options, "seeds", "non-negative ints", _is_seed)
        instructions = [None] * self.num_envs
        if options.get("instructions") is not None:
            instructions = self._field(options, "instructions", "strings", lambda s: isinstance(s, str))
        prefixes = [None] * self.num_envs
        if options.get("prefixes") is not None:
            prefixes = self._field(options, "prefixes", "(T0, A) action arrays", lambda p: np.ndim(p) == 2)
        seeds = [int(s) for s in seeds]
        every_frame = bool(options.get("every_frame", True))
        result = self._call("reset", [(tasks[s], seeds[s], instructions[s], prefixes[s], every_frame) for s in self._slices])
        result["task"] = np.array(tasks, dtype=object)
        result["seed"] = np.array(seeds, np.int64)
        self._info = result
        return {"image": result["image"], "state": result["state"]}, self._infos()

    def step(self, actions):
        """Runs one (K, A) chunk in every running episode; see the class docstring for the outputs."""
        if self._info is None:
            raise RuntimeError("call reset() with tasks and seeds before step()")
        actions = np.asarray(actions, dtype=np.float32)
        if actions.shape != self.action_space.shape:  # (B, K, A)
            raise ValueError(f"actions must have shape (num_envs, chunk_size, action_dim) = "
                             f"{self.action_space.shape}, got {actions.shape}")
        if not np.isfinite(actions).all():
            raise ValueError("actions must be finite")
        actions = np.clip(actions, -1.0, 1.0)
        result = self._call("step", [(actions[s],) for s in self._slices])
        self._info.update(step=result["step"], success=result["success"])
        infos = {**self._infos(), **{key: result[key] for key in ("frames", "rewards", "executed", "env_states")}}
        obs = {"image": result["frames"][:, -1].copy(), "state": result["state"]}  # not a view into infos["frames"]
        rewards = np.nansum(result["rewards"], axis=1)  # (B,); 0 where nothing was executed
        return obs, rewards, result["terminated"], result["truncated"], infos

    def close_extras(self, **kwargs: Any) -> None:
        """Stops the workers (or closes the in-process environments)."""
        if self._local is not None:
            self._local.close()
            self._local = None
        if self.workers is not None:
            if not (self._healthy and _shared.keep(self._pool_key, self.workers)):
                self.workers.close()
            self.workers = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _field(self, options: dict[str, Any], name: str, kind: str, valid: Callable[[Any], bool]) -> list[Any]:
        """``options[name]`` as a list of B valid values, or ValueError naming the field."""
        values = options.get(name)
        if isinstance(values, str) or not hasattr(values, "__len__") or len(values) != self.num_envs:
            raise ValueError(f'reset options need "{name}": {self.num_envs} {kind}, got {values!r}')
        values = list(values)
        if not all(valid(v) for v in values):
            raise ValueError(f'reset options "{name}" must be {self.num_envs} {kind}, got {values!r}')
        return values

    def _call(self, method: str, args: list[tuple[Any, ...]]) -> dict[str, np.ndarray]:
        """Runs ``method`` on every slice (one args tuple each); returns the results joined over B."""
        if self._local is not None:
            return getattr(self._local, method)(*args[0])
        if self.workers is None:
            raise RuntimeError("the env is closed")
        try:
            parts = self.workers.call_each(method, args)  # a worker that dies mid-rollout loses its episodes: raises
        except BaseException:
            self._healthy = False  # a dead or failed worker is not passed on to the next env
            raise
        return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}

    def _infos(self) -> dict[str, np.ndarray]:
        keys = ("instruction", "step", "task", "seed", "success", "prefix_steps")
        return {key: self._info[key].copy() for key in keys}


def _is_seed(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 0


MAX_IDLE_POOLS = 3
"""Idle pools a `shared_simulator_processes` block keeps, the most recently closed: an experiment's
envs come in a handful of settings. An idle process has closed its scenes but still holds its
interpreter, MuJoCo, its renderer and torch (about 0.5 GB, benchmarks/scene_memory.py), so a pool
of new settings stops them all first (`_SharedPools.lease`)."""


class _SharedPools:
    """The idle worker pools of a `shared_simulator_processes` block, by the settings they host."""

    def __init__(self) -> None:
        self.active = False
        self._idle: list[tuple[tuple, Workers]] = []  # oldest first

    def lease(self, key: tuple) -> Workers | None:
        """An idle pool of these settings, now the caller's alone; None outside a block or when none
        waits, and then the idle pools are stopped: each of their processes holds half a GB even
        without its scenes (an experiment ran out of 24 GB with three two-camera pools idle beside
        two working, when idle pools still kept their scenes)."""
        for index in range(len(self._idle) - 1, -1, -1):
            if self._idle[index][0] == key:
                return self._idle.pop(index)[1]
        self.close()
        return None

    def keep(self, key: tuple, workers: Workers) -> bool:
        """Keeps `workers` for the next env of these settings (stopping the oldest idle pool past
        `MAX_IDLE_POOLS`); False outside a block, where the caller stops them.

        A kept pool first closes its scenes: an idle pool costs its processes only, not the
        gigabytes of scenes they built (two cameras on MT10: about 4 GB a process), which the next
        env builds again in about half a second each (benchmarks/scene_memory.py)."""
        if not self.active:
            return False
        try:
            workers.call_each("close", [()] * len(workers.pids()))
        except RuntimeError:  # a worker died since its last call: not worth keeping
            return False
        self._idle.append((key, workers))
        while len(self._idle) > MAX_IDLE_POOLS:
            self._idle.pop(0)[1].close()
        return True

    def close(self) -> None:
        for _, workers in self._idle:
            workers.close()
        self._idle.clear()


_shared = _SharedPools()


@contextlib.contextmanager
def shared_simulator_processes() -> Iterator[None]:
    """Within the block, closed `SimVectorEnv` s keep their worker processes for the next env of the
    same settings (runner, worker count, env config, gap, instruction split); they stop at its end.
    Nested blocks share the outer one's processes."""
    if _shared.active:
        yield
        return
    _shared.active = True
    try:
        yield
    finally:
        _shared.active = False
        _shared.close()
