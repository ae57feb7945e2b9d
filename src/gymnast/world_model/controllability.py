"""Does the world model respond to actions the way the simulator does?

A model that ignores its actions and draws a plausible average future can score well on fidelity
tables and still be useless for RL, where only the differences between actions matter. So, from
the start of held-out scenes, S different action sequences are run both in the real simulator and
in the world model: the episode's own actions and S - 1 random "reach somewhere" sequences (a
random direction held for a few steps, then another). With M[i, j] the mean PSNR of imagined
rollout i against the simulator's rollout j, a controllable model has a high diagonal: imagined
rollout i resembles real rollout i more than the real rollouts of the other sequences, and it
identifies its own sequence (argmax over j is i).

Legend: S action sequences, T steps, A action dimensions, H/W image size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.data.lerobot import EpisodeDataset
from gymnast.envs.engine import ReplayActor, play_episode
from gymnast.envs.gap import GAPS
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.world_model.base import WorldModel, rollout
from gymnast.world_model.grounding import StateSource
from gymnast.world_model.metrics import psnr, to_unit_float
from gymnast.world_model.views import replay_cameras


@dataclass(frozen=True)
class ControllabilityConfig:
    """Settings of the controllability check."""

    scenes: int = 10
    """Held-out scenes (the first episode of each) to start from; 0 skips the check."""
    sequences: int = 4
    """Action sequences S per scene: the episode's own, plus S - 1 random ones."""
    horizon: int = 32
    """Steps T of each sequence."""
    hold: int = 8
    """A random sequence keeps each random direction for this many steps."""
    seed: int = 0
    """Seed of the random sequences."""


def random_sequences(count: int, horizon: int, hold: int, action_dim: int, rng: np.random.Generator) -> np.ndarray:
    """(count, T, A) piecewise-constant random actions in [-1, 1]."""
    directions = rng.uniform(-1, 1, (count, -(-horizon // hold), action_dim)).astype(np.float32)
    return np.repeat(directions, hold, axis=1)[:, :horizon]


def simulate(env: MetaWorldEnv, seed: int, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, H, W, 3) frames the simulator renders and (T, E) its environment states after (T, A)
    actions from the scene of `seed`."""
    run = play_episode(env, ReplayActor(actions), seed, record=("frames", "env_states"))
    return np.stack(run.frames[1:]), np.stack(run.env_states[1:]).astype(np.float32)


def check_controllability(model: WorldModel, dataset: EpisodeDataset, heldout: list[int], config: ControllabilityConfig,
                          progress: bool = True, grounding: StateSource | None = None) -> dict:
    """Runs the check on the first `config.scenes` held-out scenes; returns its figures (none when
    no held-out scene can be replayed: episodes recorded on another robot have no simulator). A
    grounded model renders at the states `grounding` gives (the simulator's own, or a state model's)."""
    scenes, seen = [], set()
    worlds = {gap.env_variant for gap in GAPS.values()}
    for index in heldout:
        info = dataset.episodes[index]
        if info.env_variant in worlds and (info.task, info.seed) not in seen and dataset.lengths[index] >= config.horizon:
            seen.add((info.task, info.seed))
            scenes.append(index)
    scenes = scenes[: config.scenes]
    if not scenes:
        return {}
    rng = np.random.default_rng(config.seed)
    matrices, start_psnr = [], []
    for index in tqdm(scenes, desc="controllability", disable=not progress):
        episode = dataset.load(index)
        info = episode.info
        env = MetaWorldEnv(info.task, EnvConfig(image_size=model.image_size, horizon=config.horizon, terminate_on_success=False,
                                                cameras=replay_cameras(model)),
                           gap=_gap_name(info.env_variant))
        start = env.reset(seed=info.seed)[0]["image"]
        start_psnr.append(float(psnr(to_unit_float(torch.from_numpy(start)), to_unit_float(torch.from_numpy(episode.observed_frames[0])))))
        sequences = np.concatenate([episode.actions[None, : config.horizon].astype(np.float32),
                                    random_sequences(config.sequences - 1, config.horizon, config.hold, model.action_dim, rng)])
        simulated = [simulate(env, info.seed, s) for s in sequences]
        real = torch.from_numpy(np.stack([frames for frames, _ in simulated]))  # (S, T, H, W, 3)
        env.close()
        states = None if grounding is None else grounding.states(
            episode.full_states[0], np.zeros(model.action_dim, np.float32), episode.info.instruction, sequences,
            np.stack([env_states for _, env_states in simulated]))
        context = torch.from_numpy(start)[None, None].expand(len(sequences), 1, -1, -1, -1)
        imagined = rollout(model, context, torch.from_numpy(sequences), torch.Generator().manual_seed(config.seed),
                           states).frames  # (S, T, H, W, 3)
        pred, target = to_unit_float(imagined), to_unit_float(real)
        # M[i, j]: imagined rollout i against real rollout j, mean PSNR over the T frames.
        matrices.append(torch.stack([psnr(pred, target[j : j + 1].expand_as(target)).mean(1) for j in range(len(target))], 1).numpy())
    m = np.stack(matrices)  # (scenes, S, S)
    diagonal = np.eye(m.shape[1], dtype=bool)
    return {
        "scenes": len(scenes),
        "sequences": int(m.shape[1]),
        "horizon": config.horizon,
        "matched_psnr": round(float(m[:, diagonal].mean()), 3),
        "mismatched_psnr": round(float(m[:, ~diagonal].mean()), 3),
        "identification_accuracy": round(float((m.argmax(2) == np.arange(m.shape[1])).mean()), 3),
        "start_frame_psnr": round(float(np.mean(start_psnr)), 2),
    }


def _gap_name(env_variant: str) -> str:
    """The sim-gap level whose variant recorded the episode (the real world is "none")."""
    for name, gap in GAPS.items():
        if gap.env_variant == env_variant:
            return name
    raise ValueError(f"episodes recorded in {env_variant!r} cannot be replayed: no such world (known: "
                     f"{sorted(g.env_variant for g in GAPS.values())})")
