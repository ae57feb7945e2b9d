"""Real start states for batched rollouts: the scenes a rollout starts from, in every env kind.

Legend: R rollouts, C start frames, H/W image size, A action dimensions.

A start state is real in every environment: the imagined env starts from its camera frames, a
simulator from the (task, seed) that produced them. `Start` is the one start-state type, for the
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
    """

    task: str
    seed: int
    instruction: str
    frames: np.ndarray
    reference_actions: np.ndarray = field(default_factory=lambda: np.zeros((0, ACTION_DIM), np.float32))


def start_options(starts: Sequence[Start]) -> dict:
    """Reset options that describe `starts` to every environment (each reads what it needs)."""
    return {
        "frames": np.stack([start.frames for start in starts]),  # (R, C, H, W, 3)
        "instructions": [start.instruction for start in starts],
        "tasks": [start.task for start in starts],
        "seeds": [start.seed for start in starts],
    }


def scene_starts(scenes: Sequence[tuple[str, int]], config: EnvConfig) -> list[Start]:
    """Starts for (task, seed) scenes with their real first frames and no reference actions.

    Rendering a first frame is a reset, not an interaction: no action is taken.
    """
    starts = []
    for task, seed in scenes:
        obs, info = cached_env(task, config).reset(seed=seed)
        starts.append(Start(task, seed, info["instruction"], obs["image"][None].copy()))
    return starts


def evaluation_starts(tasks: Sequence[str], episodes: int, config: EnvConfig) -> list[Start]:
    """`episodes` starts per task from the evaluation seeds, with their real first frames."""
    return scene_starts([(task, eval_seed(i)) for task in tasks for i in range(episodes)], config)


class StartSampler:
    """`sampler(count, generator)`: start states drawn uniformly from a pool (a dataset's scenes, or
    the scenes a run practises on), or (`pool` None) fresh scenes of `tasks` from random data
    seeds; with `instruction` in place of their own (see `own_instruction`).

    A fresh scene's first frame is rendered by a reset of the real world: no action is taken, so it
    costs no real interaction, but it is a look at the real world, and `rendered` counts them.
    """

    def __init__(self, tasks: Sequence[str], pool: Sequence[Start] | None, config: EnvConfig,
                 instruction: str | None = None) -> None:
        if pool is not None and not pool:
            raise ValueError("no start states to draw from")
        self.tasks, self.pool, self.config, self.instruction = list(tasks), pool, config, instruction
        self.rendered = 0

    def __call__(self, count: int, generator: torch.Generator) -> list[Start]:
        if self.pool is not None:
            picks = torch.randint(len(self.pool), (count,), generator=generator).tolist()
            return own_instruction([self.pool[i] for i in picks], self.instruction)
        picks = torch.randint(len(self.tasks), (count,), generator=generator).tolist()
        seeds = torch.randint(DATA_SEEDS.start, DATA_SEEDS.stop, (count,), generator=generator).tolist()
        self.rendered += count
        return own_instruction(scene_starts([(self.tasks[t], seed) for t, seed in zip(picks, seeds)], self.config),
                               self.instruction)


def own_instruction(starts: Sequence[Start], instruction: str | None) -> list[Start]:
    """The starts with a user's own `instruction` in place of theirs (None: as they are)."""
    return list(starts) if instruction is None else [replace(start, instruction=instruction) for start in starts]
