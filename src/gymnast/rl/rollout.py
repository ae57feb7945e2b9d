"""Rollouts for RL: B real start states, G rollouts each, in any chunked vector environment.

Legend: R rollouts (= B starts x G), S policy calls per rollout, N action tokens per call, K
actions per chunk, A action dimensions, T actions per rollout, C start frames, H/W image size.

The environment is anything with the contract both `gymnast.envs.imagined.BatchedImaginedEnv`
and `gymnast.envs.sim_vector.SimVectorEnv` follow: a gymnasium `VectorEnv` without autoreset whose
step takes one (R, K, A) action chunk and reports the chunk's frames in ``infos["frames"]``; the
rollout engine's batched driver (`gymnast.envs.engine.run_batch`) steps it, and never asks which
one it drives. Simulators also report ``executed``, ``rewards`` and ``success`` in their infos,
and a rollout carries them when they are there (the simulator rewards read them); a world model
reports none, and its rollouts are judged on their video alone.

Rollouts start from real start states (`gymnast.envs.starts.Start`) and are scored by a `Reward`
one group at a time (`score_groups`), with what the reward may read besides the video.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from gymnasium.vector import VectorEnv

from gymnast.data.frames import Fit
from gymnast.data.keyframes import KeyframeConfig, dataset_keyframes
from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.data.schema import EXTERNAL, EpisodeInfo
from gymnast.envs.engine import run_batch
from gymnast.envs.starts import Start, start_options
from gymnast.policy.base import ActionSample, Policy, state_inputs
from gymnast.reward.base import Reward, RewardContext

EXPERTS = ("expert", "noisy_expert")  # the behaviours whose actions can serve as a reference


@dataclass(frozen=True)
class Rollouts:
    """R finished rollouts: what the policy saw and sampled, and what happened.

    Attributes:
        starts: the R start states.
        observations: (R, S, H, W, 3) uint8 the image the policy saw at each call.
        tokens: (R, S, N) int64 sampled action tokens (greedy rollouts: the argmax tokens).
        logp: (R, S, N) float32 their log-probabilities at the sampling temperature (0 if greedy).
        token_mask: (R, S, N) bool tokens whose action was executed (False after the end).
        rendered: the frames as kept: (R, T + 1, H, W, 3) uint8 the start frame, then one frame
            per action; with `hold` K, (R, 1 + T / K, H, W, 3), the start frame, then each chunk's
            last frame alone (read `frames` for one frame per action).
        actions: (R, T, A) float32 the actions executed (0 after the end).
        lengths: (R,) int64 actions each rollout executed.
        success: (R,) bool the simulator's verdict, or None (a world model has none).
        env_rewards: (R, T) float32 the simulator's per-action rewards (NaN after the end), or None.
        disagreement: (R, T) float32 a world-model ensemble's disagreement on each imagined frame
            (NaN after the end), or None (simulators and single world models report none).
        states: (R, S, D) float32 the robot state the policy was given at each call (a
            simulator's), or None (a world model imagines none).
        env_states: (R, T, E) float32 a simulator's full state after each action (NaN after the
            end), or None (a world model has none): what a reward model of states reads for real.
        hold: the actions each kept frame after the first stands for: 1, or K where every frame
            inside a chunk was its last one repeated (a simulator that rendered only the frames the
            policy reads), kept once: about a K-th of the memory (the frames are most of a real RL
            step's: 2 GB a round of 160 three-view rollouts of 150 actions, one per action).
    """

    starts: tuple[Start, ...]
    observations: torch.Tensor
    tokens: torch.Tensor
    logp: torch.Tensor
    token_mask: torch.Tensor
    rendered: torch.Tensor
    actions: torch.Tensor
    lengths: torch.Tensor
    success: torch.Tensor | None
    env_rewards: torch.Tensor | None
    disagreement: torch.Tensor | None = None
    states: torch.Tensor | None = None
    env_states: torch.Tensor | None = None
    hold: int = 1

    @property
    def frames(self) -> torch.Tensor:
        """(R, T + 1, H, W, 3) uint8 the start frame, then one frame per action; after a rollout's
        end its last frame repeats. With `hold` > 1 each call builds it anew: `select` the rollouts
        to read first."""
        if self.hold == 1:
            return self.rendered
        return torch.cat([self.rendered[:, :1], self.rendered[:, 1:].repeat_interleave(self.hold, dim=1)], dim=1)

    @property
    def instructions(self) -> list[str]:
        return [start.instruction for start in self.starts]

    def select(self, index: torch.Tensor) -> Rollouts:
        """The rollouts at `index` (R',) int64, in that order."""
        pick = index.tolist()
        optional = {name: None if getattr(self, name) is None else getattr(self, name)[index]
                    for name in ("success", "env_rewards", "disagreement", "states", "env_states")}
        return Rollouts(tuple(self.starts[i] for i in pick), self.observations[index], self.tokens[index],
                        self.logp[index], self.token_mask[index], self.rendered[index], self.actions[index],
                        self.lengths[index], **optional, hold=self.hold)


def collect_rollouts(
    env: VectorEnv,
    policy: Policy,
    starts: Sequence[Start],
    temperature: float,
    generator: torch.Generator,
    seed: int = 0,
    calls: int | None = None,
    timer: dict[str, float] | None = None,
    every_frame: bool = True,
) -> Rollouts:
    """Runs one rollout per start until every one has ended (success or horizon).

    Args:
        env: a chunked vector env with ``num_envs == len(starts)`` (see the module docstring).
        policy: samples each chunk from the latest frame and the instruction.
        starts: R real start states.
        temperature: sampling temperature; 0 takes the greedy chunk (`Policy.act`), for evaluation.
        generator: the policy's sampling generator (the RL run's own, so resumes repeat draws).
        seed: the environment's reset seed (stochastic world models draw from it).
        calls: pad to this many policy calls S when every rollout ended sooner (a simulator's
            successes), so rollouts of one env always have the same shape.
        timer: if given, ``policy_s`` (time spent sampling actions) is added to it.
        every_frame: False when nothing reads the frames inside a chunk (an evaluation that counts
            successes): a simulator renders each chunk's last frame alone (rendering is most of a
            simulator step's cost), and the rollouts keep it once (`Rollouts.hold`).
    """
    if env.num_envs != len(starts):
        raise ValueError(f"the env runs {env.num_envs} rollouts but {len(starts)} starts were given")
    count, (chunk, action_dim) = env.num_envs, env.single_action_space.shape
    samples: list[ActionSample] = []

    def act(images: np.ndarray, instructions: list[str], states: np.ndarray | None) -> np.ndarray:  # -> (R, K, A)
        began = time.perf_counter()
        given = None if states is None else torch.from_numpy(states)  # (R, D) a simulator's robot states
        samples.append(_sample(policy, torch.from_numpy(images), instructions, temperature, generator, given))
        if timer is not None:
            timer["policy_s"] = timer.get("policy_s", 0.0) + time.perf_counter() - began
        return samples[-1].actions.numpy()

    seen, states, masks, frames, actions, rewards, disagreement, success = [], [], [], [], [], [], [], None
    env_states = []
    kept_once = [False]  # for each entry of `frames`: a chunk kept as its last frame alone (the start frame is not)
    for result in run_batch(env, act, start_options(starts) | {"every_frame": every_frame}, seed):
        image, new = torch.from_numpy(result.observation), torch.from_numpy(result.frames)  # new: (R, k, H, W, 3)
        if not frames:
            frames.append(image[:, None])  # (R, 1, H, W, 3) the start frame
        repeated = not every_frame and new.shape[1] == chunk and bool((new == new[:, -1:]).all())
        valid = torch.arange(chunk)[None] < torch.from_numpy(result.executed)[:, None]  # (R, K) actions really executed
        seen.append(image)
        if result.states is not None:
            states.append(torch.from_numpy(result.states).float())
        masks.append(valid.repeat_interleave(action_dim, dim=1))  # (R, N), tokens are chunk-major
        frames.append(new[:, -1:] if repeated else new)
        kept_once.append(repeated)
        actions.append(torch.from_numpy(result.actions)[:, : new.shape[1]].float() * valid[:, : new.shape[1], None])
        if result.rewards is not None:
            rewards.append(torch.from_numpy(result.rewards))
        if result.env_states is not None:
            env_states.append(torch.from_numpy(result.env_states))
        if result.disagreement is not None:  # only where an action was executed: NaN after the end
            trusted = valid[:, : new.shape[1]]
            disagreement.append(torch.from_numpy(result.disagreement).masked_fill(~trusted, float("nan")))
        if result.success is not None:
            success = torch.from_numpy(result.success)
    tokens, logp = [sample.tokens for sample in samples], [sample.logp for sample in samples]
    for _ in range(len(tokens), calls or 0):  # nothing happens after the end: repeat, mask, NaN
        seen.append(seen[-1])
        if states:
            states.append(states[-1])
        tokens.append(torch.zeros_like(tokens[-1]))
        logp.append(torch.zeros_like(logp[-1]))
        masks.append(torch.zeros_like(masks[-1]))
        frames.append(frames[-1][:, -1:])  # the last frame, held for the chunk
        kept_once.append(True)
        actions.append(torch.zeros(count, chunk, action_dim))
        for padded in (rewards, disagreement):
            if padded:
                padded.append(torch.full((count, chunk), float("nan")))
        if env_states:
            env_states.append(torch.full_like(env_states[-1], float("nan")))
    held = all(kept_once[1:])
    if not held:  # some chunk showed more than its last frame: every chunk gets its K frames back
        frames = [f.expand(-1, chunk, -1, -1, -1) if once else f for f, once in zip(frames, kept_once)]
    mask = torch.stack(masks, dim=1)  # (R, S, N)
    return Rollouts(
        starts=tuple(starts),
        observations=torch.stack(seen, dim=1),
        tokens=torch.stack(tokens, dim=1),
        logp=torch.stack(logp, dim=1),
        token_mask=mask,
        rendered=torch.cat(frames, dim=1),
        actions=torch.cat(actions, dim=1),
        lengths=mask[:, :, ::action_dim].sum(dim=(1, 2)),
        success=success,
        env_rewards=torch.cat(rewards, dim=1) if rewards else None,
        disagreement=torch.cat(disagreement, dim=1) if disagreement else None,
        states=torch.stack(states, dim=1) if states else None,
        env_states=torch.cat(env_states, dim=1) if env_states else None,
        hold=chunk if held else 1,
    )


def _sample(policy: Policy, image: torch.Tensor, instructions: list[str], temperature: float,
            generator: torch.Generator, states: torch.Tensor | None):
    if temperature > 0:
        return policy.sample(image, instructions, temperature, generator, **state_inputs(policy, states))
    with torch.inference_mode():
        actions = policy.act(image, instructions, **state_inputs(policy, states))  # (R, K, A)
    tokens = policy.chunk_tokens(actions)
    return ActionSample(actions, tokens, torch.zeros(tokens.shape))


def score_groups(reward: Reward, rollouts: Rollouts, size: int, per_step: bool = False) -> torch.Tensor:
    """(R,) scores, reward called once per block of `size` rollouts that share a start state; with
    `per_step`, (R, T) rewards of every action (the reward must be a `StepReward`)."""
    scores = []
    score = reward.step_rewards if per_step else reward.score
    for first in range(0, len(rollouts.starts), size):
        block = rollouts.select(torch.arange(first, min(first + size, len(rollouts.starts))))
        # A reward that reads no video is handed the frames as kept, not one copy per action.
        frames = block.frames if reward.needs.video else block.rendered
        scored = score(frames, block.instructions, reward_context(block)).float()
        scores.append(scored if per_step else scored.reshape(-1))
    return torch.cat(scores)


def reward_context(rollouts: Rollouts) -> RewardContext:
    """What the rewards may read besides the video (see `RewardContext`)."""
    references = [start.reference_actions for start in rollouts.starts]
    shortest = min(len(r) for r in references)  # a block shares one start, so all have one length
    return RewardContext(
        start=torch.from_numpy(np.stack([start.frames for start in rollouts.starts])),
        reference_actions=torch.from_numpy(np.stack([r[:shortest] for r in references])),
        success=rollouts.success,
        env_rewards=rollouts.env_rewards,
        start_state=torch.from_numpy(np.stack([start.state for start in rollouts.starts])),
        start_action=torch.from_numpy(np.stack([start.prefix[-1] if len(start.prefix) else
                                                np.zeros(rollouts.actions.shape[-1], np.float32)
                                                for start in rollouts.starts])),
        actions=rollouts.actions,
        env_states=rollouts.env_states,
    )


def call_inputs(policy, batch: Rollouts, r: torch.Tensor,
                s: torch.Tensor) -> tuple[torch.Tensor, list[str], torch.Tensor, dict]:
    """What the policy read and sampled at the calls (r, s): their images, instructions and tokens,
    and the keyword arguments that give it their robot states (for a policy that reads them)."""
    instructions = batch.instructions
    states = state_inputs(policy, None if batch.states is None else batch.states[r, s])  # (m, D), a simulator's
    return batch.observations[r, s], [instructions[i] for i in r.tolist()], batch.tokens[r, s], states


def concat_rollouts(parts: list[Rollouts]) -> Rollouts:
    """One `Rollouts` of the parts in order (rollouts of one env share their shapes; parts that keep
    their frames differently are given one frame per action)."""
    hold = parts[0].hold if all(part.hold == parts[0].hold for part in parts) else 1
    tensors = {"rendered": torch.cat([part.rendered if hold > 1 else part.frames for part in parts])}
    for field in dataclasses.fields(Rollouts):
        if field.name not in ("starts", "rendered", "hold"):
            values = [getattr(part, field.name) for part in parts]
            tensors[field.name] = None if values[0] is None else torch.cat(values)
    return Rollouts(starts=tuple(start for part in parts for start in part.starts), **tensors, hold=hold)


def recorded_elsewhere(data: Path, keys: FeatureKeys = FeatureKeys()) -> bool:
    """Whether the dataset was recorded on another robot (a LeRobot dataset gymnast did not write):
    gymnast has no simulator of it, so only the world model can practise from its scenes."""
    return any(info.env_variant == EXTERNAL for info in EpisodeDataset(data, keys=keys).episodes)


def own_tasks(data: Path, named: str = "", keys: FeatureKeys = FeatureKeys()) -> tuple[str, ...]:
    """Another robot's tasks to practise: every task of the dataset that has a start state (`named`
    empty), or those `named`, comma-separated, exactly as the dataset writes them.

    Raises:
        ValueError: a named task is not one of the dataset's (the message lists them).
    """
    have = tuple(dict.fromkeys(info.task for info in EpisodeDataset(data, keys=keys).episodes if _expert_solved(info)))
    if not named:
        return have
    wanted = tuple(task.strip() for task in named.split(",") if task.strip())
    unknown = [task for task in wanted if task not in have]
    if unknown:
        raise ValueError(f"{data} has no task {unknown[0]!r} to start from; its tasks: {', '.join(map(repr, have))}")
    return wanted


def heldout_starts(starts: Sequence[Start], per_task: int, fraction: float = 0.1) -> list[Start]:
    """Up to `per_task` starts of each task from the scenes the models held out (the same scene hash
    as their training split), for evaluating where no simulator can set up a new scene; a task
    without a held-out scene lends its first training scenes."""
    from gymnast.world_model.data import is_heldout

    chosen = []
    for task in dict.fromkeys(start.task for start in starts):
        mine = [start for start in starts if start.task == task]
        held = [start for start in mine if is_heldout(EpisodeInfo(task, "", True, "expert", 0.0, start.seed), fraction)]
        chosen += (held or mine)[:per_task]
    return chosen


def tasks_with_starts(data: Path, wanted: Sequence[str], keys: FeatureKeys = FeatureKeys()) -> tuple[str, ...]:
    """The tasks a run should train on when none were named: those of `wanted` (a preset's) that
    the dataset has start states for; if it has none of them, as many of its own (alphabetically).

    Raises:
        ValueError: the dataset has no start state of any task.
    """
    have = sorted({info.task for info in EpisodeDataset(data, keys=keys).episodes if _expert_solved(info)})
    if not have:
        raise ValueError(f"{data} has no successful expert episode of any task to start from")
    return tuple(task for task in wanted if task in have) or tuple(have[: len(wanted)])


def dataset_starts(data: Path, tasks: Sequence[str] | None = None, image_size: int | None = None,
                   fit: Fit = "resize", camera: str | None = None, keyframes: KeyframeConfig | None = None,
                   keys: FeatureKeys = FeatureKeys(), cameras: Sequence[str] | None = None
                   ) -> list[Start]:
    """One start per (task, seed) scene of a dataset: its first frame, instruction and reference;
    or, with `keyframes` other than ``first``, keyframes of every episode of `tasks` recorded in the
    real world (or on another robot), each with the episode's own continuation as its reference.

    The reference of a first frame is the successful scripted-expert episode (with or without
    action noise) with the least noise in that scene; scenes with no successful expert episode are
    left out (they have no reference, and an imagined start should be one the expert solved in the
    real world).

    Args:
        data: dataset directory.
        tasks: the tasks to take starts of (None: every task).
        image_size: fit the frames to this square size by `fit`, as the models that will see them
            were trained (`gymnast.data.frames`); None: the frames as stored.
        fit: resize or crop, the models' training setting.
        camera: the dataset camera to read (default: the first whose frames exist).
        keyframes: where in the episodes to start (None or ``first``: first frames).
        keys: the dataset features read as the actions and the states (the policy's, `policy_keys`).
        cameras: several cameras whose frames a start shows side by side (a policy's and a world
            model's of several cameras), the primary first; default: `camera` alone.

    Raises:
        ValueError: no scene of `tasks` has a successful expert episode (no episode of `tasks`, for
            keyframes).
    """
    dataset = EpisodeDataset(data, camera, cameras, keys=keys)
    if image_size is not None:
        dataset = dataset.fitted(image_size, fit)
    if keyframes is not None and keyframes.sampling != "first":
        episodes = [i for i, info in enumerate(dataset.episodes) if info.in_real_world
                    and (not tasks or info.task in tasks)]
        starts = dataset_keyframes(dataset, episodes, keyframes)
        if not starts:
            raise ValueError(f"{data} has no episode of {', '.join(tasks or ['any task'])} to draw "
                             f"{keyframes.sampling} keyframes from")
        return starts
    best: dict[tuple[str, int], int] = {}
    for i, info in enumerate(dataset.episodes):
        if not _expert_solved(info) or (tasks and info.task not in tasks):
            continue
        key = (info.task, info.seed)
        if key not in best or info.noise < dataset.episodes[best[key]].noise:
            best[key] = i
    if not best:
        raise ValueError(f"{data} has no successful expert episode of {', '.join(tasks or ['any task'])} to start from")
    starts = []
    for key in sorted(best):  # a first frame is decoded alone, not its episode's video
        columns = dataset.columns(best[key])
        starts.append(Start(columns.info.task, columns.info.seed, columns.info.instruction,
                            dataset.first_frame(best[key])[None], columns.actions.astype(np.float32),
                            state=np.asarray(columns.full_states[0], np.float32)))
    return starts


def _expert_solved(info: EpisodeInfo) -> bool:
    """A scripted expert (with or without noise) solved this episode's scene: a start with a reference."""
    return info.behaviour in EXPERTS and info.success
