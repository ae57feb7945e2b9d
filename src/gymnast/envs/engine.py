"""The rollout engine: the only code that steps episodes, in every kind of environment.

Legend: R rollouts stepped together, K actions per chunk, k actions of a chunk executed, T actions
per episode, A action dimensions, H/W image size.

Every episode in the project is an actor choosing a chunk of K >= 1 actions that the env then
executes open-loop, as a robot would. Two functions step envs, one per granularity:

- `play_chunk` executes one chunk in one Meta-World episode (the real world or a software
  simulator) and decides what the episode's outcome is: success at any step, the end at
  ``terminated`` (success) or ``truncated`` (horizon). `play_episode` plays a whole episode with it
  in this process, for the per-episode process pools (`gymnast eval`, `gymnast collect`, the gap
  report, the controllability check), and `gymnast.envs.sim_vector.SimVectorEnv`'s workers call it
  for each of their episodes, so the RL loop's real and simulated rollouts are stepped by it too.
- `run_batch` drives R rollouts in any chunked vector env (`SimVectorEnv` for the real world and
  the simulators, `gymnast.envs.imagined.BatchedImaginedEnv` for a world model) with one batched
  actor call per chunk: RL, RL evaluation, WorldGym, the imagination report, Iter-SFT
  (`gymnast.rl.rollout.collect_rollouts`), the reward-hacking watch's replays and the plans made in
  imagination (`gymnast.eval.actors.ImaginedPlanActor`). The world model's ``step`` is called
  for rollouts only below it, by the imagined env, one chunk per call.

Why two drivers and not one: a scripted expert acts from the simulator state at every step, so it
must run where the env lives, and `gymnast eval` (perturbed starts, videos) and `gymnast collect`
(states, env states, rewards per step) record whole episodes in worker processes; shipping every
step of those through a vector env's pipes would only add copies. Policies and world models, on
the other hand, are fast only in batches, which is what `run_batch` is for. Since a vector env's
Meta-World episodes run `play_chunk` as well, `gymnast eval` and WorldGym measure real success
with the same code.

The actor and what is recorded are the parameters: an `Actor` returns the next chunk (a policy,
a scripted behaviour via `ScriptedActor`, fixed actions via `ReplayActor`, a plan made in
imagination); ``record`` names the per-step fields an `EpisodeRun` keeps (`RECORDABLE`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from gymnasium.vector import VectorEnv

from gymnast.envs.experts import Behaviour
from gymnast.envs.metaworld import MetaWorldEnv

RECORDABLE = ("frames", "states", "env_states", "rewards", "successes")
"""Per-step fields an `EpisodeRun` can record; the actions executed are always kept."""


class Actor(Protocol):
    """Plays one Meta-World episode: called with the env and its latest observation whenever the
    previous chunk has run out."""

    def __call__(self, env: MetaWorldEnv, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(K, A) the next K >= 1 actions, executed open-loop (stopping early if the episode ends)."""
        ...


class ScriptedActor:
    """A scripted behaviour (`gymnast.envs.experts`) as an `Actor`: a chunk of one action, read
    from the simulator state."""

    def __init__(self, behaviour: Behaviour) -> None:
        self._behaviour = behaviour

    def __call__(self, env: MetaWorldEnv, obs: dict[str, np.ndarray]) -> np.ndarray:
        return self._behaviour(env.env_state)[None]  # (1, A)


class ReplayActor:
    """Fixed (T, A) actions as an `Actor`: all of them as one chunk, executed open-loop.

    Raises:
        ValueError: called again, because the episode outlasted the actions.
    """

    def __init__(self, actions: np.ndarray) -> None:
        self._actions, self._played = actions, False

    def __call__(self, env: MetaWorldEnv, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self._played:
            raise ValueError(f"the {len(self._actions)} replayed actions ran out before the episode on {env.task} ended")
        self._played = True
        return self._actions


@dataclass
class EpisodeRun:
    """One Meta-World episode being played: its env, where it stands and what it recorded.

    The recorded lists hold what ``record`` named (the others stay empty): ``frames`` (H, W, 3)
    uint8 camera images, ``states`` proprioception, ``env_states`` (E,) float64 simulator states,
    each with the start first (T + 1 entries); ``rewards`` and ``successes`` per action (T).
    """

    env: MetaWorldEnv
    obs: dict[str, np.ndarray]
    record: frozenset[str]
    steps: int = 0
    success: bool = False  # at any step so far
    terminated: bool = False
    truncated: bool = False
    actions: list[np.ndarray] = field(default_factory=list)
    frames: list[np.ndarray] = field(default_factory=list)
    states: list[np.ndarray] = field(default_factory=list)
    env_states: list[np.ndarray] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    successes: list[bool] = field(default_factory=list)
    prefix_steps: int = 0  # real actions replayed to restore the keyframe the episode starts from

    @property
    def done(self) -> bool:
        return self.terminated or self.truncated

    @property
    def instruction(self) -> str:
        return self.env.instruction

    def keep(self, obs: dict[str, np.ndarray], reward: float | None = None, success: bool | None = None) -> None:
        """Records what ``record`` names of one observation (and the step that led to it)."""
        self.obs = obs
        values = {"frames": obs["image"], "states": obs["state"], "env_states": self.env.env_state.copy()}
        if reward is not None:
            values |= {"rewards": reward, "successes": success}
        for name, value in values.items():
            if name in self.record:
                getattr(self, name).append(value)


def start_episode(env: MetaWorldEnv, seed: int, instruction: str | None = None,
                  record: Collection[str] = (), prefix: np.ndarray | None = None) -> EpisodeRun:
    """Resets `env` to the scene of `seed` (with `instruction`, or the env's own), or to the keyframe
    that `prefix` (T0, A) actions reach from it, and starts recording there."""
    unknown = set(record) - set(RECORDABLE)
    if unknown:
        raise ValueError(f"cannot record {sorted(unknown)}; recordable: {RECORDABLE}")
    obs, info = env.reset(seed=seed, options={"instruction": instruction, "prefix": prefix})
    run = EpisodeRun(env, obs, frozenset(record), prefix_steps=int(info.get("prefix_steps", 0)))
    run.keep(obs)
    return run


def play_chunk(run: EpisodeRun, chunk: np.ndarray,
               every_frame: bool = True) -> list[tuple[dict[str, np.ndarray], float]]:
    """Executes (K, A) actions open-loop, without looking at the new frames, until the chunk or the
    episode ends; returns (observation, reward) of each action executed (none once it has ended).

    Unless `every_frame` or the run records frames, only the frame the actor reads next (the
    chunk's last, or the episode's end) is rendered: rendering is most of a step's cost, and the
    others' observations have no images (`MetaWorldEnv.step`'s ``observe``)."""
    steps = []
    every_frame = every_frame or "frames" in run.record
    for j, action in enumerate(chunk):
        if run.done:
            break
        observe = every_frame or j == len(chunk) - 1
        step = run.env.step(action) if observe else run.env.step(action, observe=False)
        obs, reward, run.terminated, run.truncated, info = step
        run.steps += 1
        run.success |= bool(info["success"])
        run.actions.append(action)
        run.keep(obs, reward, info["success"])
        steps.append((obs, reward))
    return steps


def play_episode(env: MetaWorldEnv, actor: Actor, seed: int, record: Collection[str] = (),
                 instruction: str | None = None) -> EpisodeRun:
    """Plays one episode of `env` from the scene of `seed` to its end (success or horizon), with
    `instruction` (a user's own wording) or the env's own.

    Raises:
        ValueError: the actor returned something other than a non-empty (K, A) chunk.
    """
    run = start_episode(env, seed, instruction, record=record)
    while not run.done:
        chunk = np.asarray(actor(env, run.obs))  # (K, A)
        if chunk.ndim != 2 or len(chunk) == 0:
            raise ValueError(f"an actor must return a (K, A) chunk with K >= 1, got shape {chunk.shape}")
        play_chunk(run, chunk, every_frame=False)  # the actor reads each chunk's last frame alone
    return run


BatchActor = Callable[[np.ndarray, list[str], "np.ndarray | None"], np.ndarray]
"""Maps the latest (R, H, W, 3) uint8 images, the R instructions and the (R, D) robot states (a
simulator's; None from a world model, which imagines none) to (R, K, A) actions."""


@dataclass(frozen=True)
class ChunkResult:
    """What one actor call of `run_batch` did to the R rollouts.

    Attributes:
        observation: (R, H, W, 3) uint8 the images the actor saw.
        states: (R, D) float32 the robot states the actor was given, or None (a world model's).
        actions: (R, K, A) the actions it chose (as it returned them).
        frames: (R, k, H, W, 3) uint8 a frame per action; k < K only at an imagined horizon, and a
            rollout that ended shows its final frame.
        executed: (R,) int64 actions each rollout executed (0 once it had ended).
        rewards: (R, k) float32 a simulator's per-action rewards (NaN where none was executed), or
            None (a world model has none).
        success: (R,) bool a simulator's success at any step so far, or None.
        disagreement: (R, k) float32 a world-model ensemble's disagreement on each frame, or None
            (simulators and single world models report none).
        env_states: (R, k, E) float32 a simulator's full state after each action (NaN where none
            was executed), or None (a world model has none).
    """

    observation: np.ndarray
    states: np.ndarray | None
    actions: np.ndarray
    frames: np.ndarray
    executed: np.ndarray
    rewards: np.ndarray | None
    success: np.ndarray | None
    disagreement: np.ndarray | None = None
    env_states: np.ndarray | None = None


def run_batch(env: VectorEnv, actor: BatchActor, options: dict[str, Any], seed: int = 0,
              max_calls: int | None = None) -> Iterator[ChunkResult]:
    """Runs R rollouts in a chunked vector env, one actor call per chunk, until all have ended.

    The env is anything with the contract of `SimVectorEnv` and `BatchedImaginedEnv`: a gymnasium
    `VectorEnv` without autoreset whose step takes one (R, K, A) chunk and reports its frames in
    ``infos["frames"]`` (simulators also report ``executed``, ``rewards`` and ``success``; an
    imagined env ``disagreement`` when its world model is an ensemble, and ``executed`` when it
    stops rollouts there).

    Args:
        env: the vector env.
        actor: chooses each chunk.
        options: the reset options that start the R rollouts (`gymnast.envs.starts.start_options`).
        seed: the env's reset seed (stochastic world models draw from it).
        max_calls: stop after this many chunks even if some rollouts are still running.

    Yields:
        A `ChunkResult` per chunk, in order.
    """
    obs, infos = env.reset(seed=seed, options=options)
    instructions = [str(i) for i in infos["instruction"]]
    ended = np.zeros(env.num_envs, dtype=bool)
    calls = 0
    while not ended.all() and (max_calls is None or calls < max_calls):
        image, states = obs["image"], obs.get("state")
        actions = actor(image, instructions, states)
        obs, _, terminated, truncated, infos = env.step(actions)
        frames = infos["frames"]
        executed = np.where(ended, 0, infos.get("executed", np.full(env.num_envs, frames.shape[1])))
        rewards = np.asarray(infos["rewards"], dtype=np.float32) if "rewards" in infos else None
        success = np.asarray(infos["success"], dtype=bool) if "success" in infos else None
        disagreement = np.asarray(infos["disagreement"], dtype=np.float32) if "disagreement" in infos else None
        env_states = np.asarray(infos["env_states"], dtype=np.float32) if "env_states" in infos else None
        ended |= np.asarray(terminated) | np.asarray(truncated)
        calls += 1
        yield ChunkResult(image, states, actions, frames, executed, rewards, success, disagreement, env_states)

