"""Real start states for batched rollouts: the scenes a rollout starts from, in every env kind.

Legend: R rollouts, C start frames, H/W image size, A action dimensions.

A start state is real in every environment: the imagined env starts from its camera frames, a
simulator from the (task, seed) that produced them and, for a keyframe in the middle of an
episode, the actions that led there from the scene's first frame (its ``prefix``, replayed
exactly by the simulator's reset). `Start` is the one start-state type, for the
batched rollouts and for `gymnast.envs.imagined.ImaginedEnv` alike. Training draws them from data seeds (a
dataset's scenes, or fresh ones in a simulator); evaluation takes them from the evaluation seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import torch

from gymnast.config import EnvConfig
from gymnast.envs.metaworld import ACTION_DIM
from gymnast.envs.parallel import cached_env
from gymnast.envs.tasks import DATA_SEEDS, eval_seed


@dataclass(frozen=True)
class Start:
    """A real start state.

    Attributes:
        task: Meta-World task name.
        seed: the episode seed that fixes the initial state (a data seed for training).
        instruction: the task in words, as the policy and the judge read it.
        frames: (C, H, W, 3) uint8 real camera frames, the last one being "now".
        reference_actions: (T_ref, A) float32 a demonstration's actions from this state (what the
            verified reward imagines); empty (the default) where there is none.
        prefix: (T0, A) float32 the real actions from the scene's first frame to this one: empty
            for a first frame; a simulator restores the keyframe by replaying them.
        state: (S,) float32 the recorded state at this frame (the dataset's environment state where
            it has one, else its ``observation.state``), what a grounded world model starts from;
            empty where it is not known.
    """

    task: str
    seed: int
    instruction: str
    frames: np.ndarray
    reference_actions: np.ndarray = field(default_factory=lambda: np.zeros((0, ACTION_DIM), np.float32))
    prefix: np.ndarray = field(default_factory=lambda: np.zeros((0, ACTION_DIM), np.float32))
    state: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))


def start_options(starts: Sequence[Start]) -> dict:
    """Reset options that describe `starts` to every environment (each reads what it needs)."""
    return {
        "frames": np.stack([start.frames for start in starts]),  # (R, C, H, W, 3)
        "instructions": [start.instruction for start in starts],
        "tasks": [start.task for start in starts],
        "seeds": [start.seed for start in starts],
        "prefixes": [start.prefix for start in starts],
        "states": [start.state for start in starts],  # recorded where the start carries one
    }


def scene_starts(scenes: Sequence[tuple[str, int]], config: EnvConfig) -> list[Start]:
    """Starts for (task, seed) scenes with their real first frames and no reference actions.

    Rendering a first frame is a reset, not an interaction: no action is taken.
    """
    starts = []
    for task, seed in scenes:
        obs, info = cached_env(task, config).reset(seed=seed)
        starts.append(Start(task, seed, info["instruction"], obs["image"][None].copy(),
                            state=np.asarray(info["env_state"], np.float32)))
    return starts


def evaluation_starts(tasks: Sequence[str], episodes: int, config: EnvConfig) -> list[Start]:
    """`episodes` starts per task from the evaluation seeds, with their real first frames."""
    return scene_starts([(task, eval_seed(i)) for task in tasks for i in range(episodes)], config)


class StartSampler:
    """`sampler(count, generator)`: `count` start states, the tasks taking turns from a random first
    one, each a random scene of its task: from a pool (a dataset's scenes, or the scenes a run
    practises on), or (`pool` None) a fresh scene from a random data seed; with `instruction` in
    place of their own (see `own_instruction`).

    Taking turns keeps every step's batch balanced over the tasks (a step does not happen to
    practise one task only), and it bounds how many environments of each task a simulator worker
    keeps: about count / tasks of each, where independent draws made it build up to `count` of
    every task over a run.

    A fresh scene's first frame is rendered by a reset of the real world: no action is taken, so it
    costs no real interaction, but it is a look at the real world, and `rendered` counts them.
    """

    def __init__(self, tasks: Sequence[str], pool: Sequence[Start] | None, config: EnvConfig,
                 instruction: str | None = None) -> None:
        if pool is not None and not pool:
            raise ValueError("no start states to draw from")
        self.config, self.instruction = config, instruction
        self.pool = None if pool is None else {task: [s for s in pool if s.task == task] for task in
                                               dict.fromkeys(start.task for start in pool)}
        self.tasks = list(self.pool) if self.pool is not None else list(tasks)
        self.rendered = 0

    def __call__(self, count: int, generator: torch.Generator) -> list[Start]:
        first = int(torch.randint(len(self.tasks), (1,), generator=generator))
        turns = [self.tasks[(first + i) % len(self.tasks)] for i in range(count)]
        if self.pool is not None:
            picks = [self.pool[task][int(torch.randint(len(self.pool[task]), (1,), generator=generator))]
                     for task in turns]
            return own_instruction(picks, self.instruction)
        seeds = torch.randint(DATA_SEEDS.start, DATA_SEEDS.stop, (count,), generator=generator).tolist()
        self.rendered += count
        return own_instruction(scene_starts(list(zip(turns, seeds)), self.config), self.instruction)


def own_instruction(starts: Sequence[Start], instruction: str | None) -> list[Start]:
    """The starts with a user's own `instruction` in place of theirs (None: as they are)."""
    return list(starts) if instruction is None else [replace(start, instruction=instruction) for start in starts]
