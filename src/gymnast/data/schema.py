"""The episode: what one rollout in an environment records, independent of how it is stored.

An episode of T steps has T actions and T + 1 observations: observation t is what the camera saw
before action t, and observation T is the result of the last action (the frame a judge needs to
see whether the task was done). Storage formats that want one row per frame pad the last row's
action; see `gymnast.data.lerobot`.

Legend: T steps, H/W image height/width, S proprioceptive state size, E full environment state
size, A action dimensions.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from gymnast.envs.experts import SCRIPTED_BEHAVIOURS
from gymnast.utils.images import tile_views

POLICY = "policy"
EXTERNAL = "external"
"""The `EpisodeInfo.env_variant` of an episode recorded on another robot (a dataset gymnast did not write)."""
BEHAVIOURS = (*SCRIPTED_BEHAVIOURS, POLICY)
"""How the actions of an episode were produced.

expert: the task's scripted Meta-World policy; noisy_expert: the same with Gaussian action noise;
random: uniform random actions; wrong_task_expert: the scripted policy of another task (a
plausible-looking failure); near_miss_expert: the task's scripted policy acting as if the objects
and the goal were a few centimetres off (its hand misses them; `gymnast.envs.experts`); policy: a learned policy's own rollouts from the camera image,
recorded as ``policy`` or ``policy-<tag>`` (see `policy_behaviour`).
"""
_POLICY_TAG = re.compile(r"[0-9a-z]+")


def policy_behaviour(tag: str) -> str:
    """The behaviour name of one learned policy's rollouts: ``policy-<tag>``.

    The tag (lowercase letters and digits) names the policy and its sampling settings. It lives
    in the behaviour, hence in the episode key, so that one dataset can hold several policies'
    rollouts from the same seeds and noise levels without a rerun mistaking one for another. The
    noise field, a float, cannot carry it, and a new `EpisodeInfo` field would be a metadata
    column that every dataset recorded before it lacks.

    Raises:
        ValueError: the tag is empty or has other characters.
    """
    if not _POLICY_TAG.fullmatch(tag):
        raise ValueError(f"a policy tag is lowercase letters and digits, got {tag!r}")
    return f"{POLICY}-{tag}"


def behaviour_kind(behaviour: str) -> str:
    """The behaviour without its policy tag: ``policy-3f2a9c1e`` -> ``policy``; others unchanged."""
    kind, dash, tag = behaviour.partition("-")
    return POLICY if kind == POLICY and dash and _POLICY_TAG.fullmatch(tag) else behaviour


def episode_key(env_variant: str, task: str, behaviour: str, noise: float, seed: int) -> str:
    """The identity of an episode's recipe: the same recipe always yields the same episode."""
    return f"{env_variant}/{task}/{behaviour}/{noise:g}/{seed}"


@dataclass(frozen=True)
class EpisodeInfo:
    """Per-episode facts that are not per-frame data.

    Attributes:
        task: Meta-World task name, e.g. ``drawer-open-v3``.
        instruction: the natural-language instruction given with the episode.
        success: whether the task was achieved at any step of the episode.
        behaviour: one of `BEHAVIOURS`, a learned policy's with its tag (`policy_behaviour`).
        noise: standard deviation of the Gaussian noise added to the behaviour's actions.
        seed: the environment seed that fixed the initial state.
        env_variant: which world the episode was recorded in, e.g. ``real`` or ``sim-gap-mild``.
    """

    task: str
    instruction: str
    success: bool
    behaviour: str
    noise: float
    seed: int
    env_variant: str = "real"

    def __post_init__(self) -> None:
        if behaviour_kind(self.behaviour) not in BEHAVIOURS:
            raise ValueError(
                f"EpisodeInfo.behaviour must be one of {BEHAVIOURS} or {POLICY}-<tag>, got {self.behaviour!r}"
            )

    @property
    def in_real_world(self) -> bool:
        """Recorded in the real world, or on another robot: what its states and frames show
        happened, unlike an episode of the software simulator with its sim-to-real gap."""
        return self.env_variant in ("real", EXTERNAL)

    @property
    def key(self) -> str:
        """Identifies the episode's recipe, so a resumed collection knows what is already done."""
        return episode_key(self.env_variant, self.task, self.behaviour, self.noise, self.seed)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def fullest_states(states: np.ndarray, env_states: np.ndarray) -> np.ndarray:
    """The environment states where they were recorded (objects and goal too), else the robot's own."""
    return env_states if env_states.shape[1] else states


@dataclass(frozen=True)
class EpisodeColumns:
    """An episode's recorded vectors and facts: an `Episode` without its frames, what a dataset
    gives without decoding a video (`gymnast.data.lerobot.EpisodeDataset.columns`). The fields
    are `Episode`'s."""

    states: np.ndarray
    env_states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    successes: np.ndarray
    info: EpisodeInfo

    @property
    def full_states(self) -> np.ndarray:
        """(T+1, S) as `Episode.full_states`."""
        return fullest_states(self.states, self.env_states)


@dataclass(frozen=True)
class Episode:
    """One recorded episode.

    Attributes:
        frames: (T+1, H, W, 3) uint8 RGB camera images of the primary camera.
        states: (T+1, S) float32 proprioception: hand position xyz and gripper opening.
        env_states: (T+1, E) float32 the full Meta-World observation vector (objects and goal).
        actions: (T, A) float32 actions in [-1, 1]: hand displacement xyz and gripper effort.
        rewards: (T,) float32 Meta-World's dense reward for each step.
        successes: (T,) bool ``info["success"]`` after each step.
        info: per-episode facts.
        views: every camera's (T+1, H, W, 3) uint8 frames by camera name, the primary first (its
            frames are `frames`); empty when only `frames` were recorded, from an unnamed camera.
    """

    frames: np.ndarray
    states: np.ndarray
    env_states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    successes: np.ndarray
    info: EpisodeInfo
    views: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def full_states(self) -> np.ndarray:
        """(T+1, S) the fullest state recorded: the environment state where there is one (objects
        and goal too), else the robot's own; what state models and grounded world models read."""
        return fullest_states(self.states, self.env_states)

    def __post_init__(self) -> None:
        n_steps = len(self.actions)
        expected = {
            "frames": (n_steps + 1, None, None, 3),
            "states": (n_steps + 1, None),
            "env_states": (n_steps + 1, None),
            "actions": (n_steps, None),
            "rewards": (n_steps,),
            "successes": (n_steps,),
        }
        for name, shape in expected.items():
            actual = getattr(self, name).shape
            if len(actual) != len(shape) or any(e is not None and e != a for e, a in zip(shape, actual)):
                raise ValueError(
                    f"Episode.{name} has shape {actual}, expected {shape} "
                    f"(None = any) for {n_steps} actions"
                )
        if self.frames.dtype != np.uint8:
            raise ValueError(f"Episode.frames must be uint8, got {self.frames.dtype}")
        for name, frames in self.views.items():
            if frames.shape != self.frames.shape or frames.dtype != np.uint8:
                raise ValueError(f"Episode.views[{name!r}] is {frames.shape} {frames.dtype}, expected "
                                 f"{self.frames.shape} uint8 like Episode.frames")
        primary = next(iter(self.views.values()), self.frames)
        if primary is not self.frames and not np.array_equal(primary, self.frames):
            raise ValueError(f"Episode.views[{next(iter(self.views))!r}] (the first, primary view) must be Episode.frames")

    @property
    def length(self) -> int:
        """Number of steps (actions) T."""
        return len(self.actions)

    @property
    def observed_frames(self) -> np.ndarray:
        """(T+1, H, V*W, 3) uint8: every camera read, side by side in `views`' order, as the env
        shows them to a policy of these cameras (`gymnast.utils.images.tile_views`); `frames`
        where one camera was read."""
        return tile_views(list(self.views.values())) if len(self.views) > 1 else self.frames
