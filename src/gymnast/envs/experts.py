"""Scripted behaviours that produce demonstrations and deliberate failures.

Meta-World ships a hand-written policy per task that reads the full simulator state. Datasets
need more than its successes: world models and judges must also see what failure looks like, so
there are noisy experts, random actions, the expert of another task (motion that looks
purposeful but does the wrong thing), and near misses: the task's own expert acting as if the
objects and the goal were a few centimetres away from where they are, so its hand closes on the
air beside the handle, puck, button or peg and nothing moves. A world model that saw only
successes learns that the object moves when the hand comes near; near misses make it earn "the
object moves" by contact.
"""

from __future__ import annotations

import warnings
import zlib
from typing import Protocol

import numpy as np
from metaworld.policies import ENV_POLICY_MAP

from gymnast.envs.tasks import MT50, check_task

SCRIPTED_BEHAVIOURS = ("expert", "noisy_expert", "random", "wrong_task_expert", "near_miss_expert")
"""The behaviours that act from the simulator state (`make_behaviour`); the episode schema names
them (`gymnast.data.schema.BEHAVIOURS`)."""

# Meta-World's experts warn on every step whose command they clip to [-1, 1]; clipping is the
# intended behaviour of their proportional controllers, so the warning is only noise.
warnings.filterwarnings("ignore", message=r"Constant\(s\) may be too high")


class Behaviour(Protocol):
    """Maps the simulator state to an action in [-1, 1]^4."""

    def __call__(self, env_state: np.ndarray) -> np.ndarray: ...


class ScriptedExpert:
    """Meta-World's scripted policy for `task`, with optional Gaussian action noise.

    Args:
        task: whose policy to run.
        noise: standard deviation of the noise added to every action (then clipped to [-1, 1]).
        rng: source of the noise.
    """

    def __init__(self, task: str, noise: float = 0.0, rng: np.random.Generator | None = None) -> None:
        self._policy = ENV_POLICY_MAP[check_task(task)]()
        self._noise = noise
        self._rng = rng or np.random.default_rng(0)

    def __call__(self, env_state: np.ndarray) -> np.ndarray:
        action = np.asarray(self._policy.get_action(env_state), dtype=np.float32)
        if self._noise > 0:
            action = action + self._rng.normal(0.0, self._noise, size=action.shape).astype(np.float32)
        return np.clip(action, -1.0, 1.0)


NEAR_MISS_CM = 5.0
"""How far a near miss's expert believes the scene to be from where it is, horizontally."""

# Where Meta-World's 39-number state holds positions (x, y, z): the first and second object, the
# same two one step before, and the goal. The hand (0:3, 18:21) is left where it is.
_SCENE_POSITIONS = (slice(4, 7), slice(11, 14), slice(22, 25), slice(29, 32), slice(36, 39))


class NearMissExpert:
    """The task's scripted policy acting on a state whose objects and goal are moved by `offset`
    (metres; the hand stays): it reaches, grasps and pushes a few centimetres beside them.

    Args:
        task: whose policy to run.
        offset: (3,) displacement of every object position and of the goal in the state the policy reads.
    """

    def __init__(self, task: str, offset: np.ndarray) -> None:
        self._expert = ScriptedExpert(task)
        self._offset = np.asarray(offset, dtype=np.float64)

    def __call__(self, env_state: np.ndarray) -> np.ndarray:
        believed = np.array(env_state, dtype=np.float64)
        for where in _SCENE_POSITIONS:
            believed[where] += self._offset
        return self._expert(believed)


def near_miss_offset(rng: np.random.Generator) -> np.ndarray:
    """A horizontal displacement of `NEAR_MISS_CM` in a random direction, in metres."""
    angle = rng.uniform(0.0, 2 * np.pi)
    return NEAR_MISS_CM / 100 * np.array([np.cos(angle), np.sin(angle), 0.0])


class RandomActions:
    """Uniform random actions (the noise argument is unused: they are as noisy as it gets)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self._rng = rng

    def __call__(self, env_state: np.ndarray) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, size=4).astype(np.float32)


def wrong_task_for(task: str, seed: int) -> str:
    """A task other than `task`, picked deterministically from the seed."""
    others = [t for t in MT50 if t != task]
    return others[zlib.crc32(f"{task}/{seed}".encode()) % len(others)]


def make_behaviour(behaviour: str, task: str, noise: float, seed: int) -> Behaviour:
    """Builds the named behaviour (one of `SCRIPTED_BEHAVIOURS`) for one episode."""
    rng = np.random.default_rng([zlib.crc32(task.encode()), seed, 2])
    if behaviour in ("expert", "noisy_expert"):
        return ScriptedExpert(task, noise, rng)
    if behaviour == "random":
        return RandomActions(rng)
    if behaviour == "wrong_task_expert":
        return ScriptedExpert(wrong_task_for(task, seed), noise, rng)
    if behaviour == "near_miss_expert":
        return NearMissExpert(task, near_miss_offset(rng))
    raise ValueError(f"unknown behaviour {behaviour!r}; choose one of {SCRIPTED_BEHAVIOURS}")
