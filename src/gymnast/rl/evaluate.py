"""What an RL run measures besides its training reward: success on the evaluation seeds, in its
own env and in the real world, and how often an imagined verdict survives the real world.

Legend: R rollouts, T actions, K actions per chunk, A action dimensions.

Evaluation here uses the training loop's machinery (vector envs, batched greedy chunks) rather
than `gymnast eval`, so that it runs in any env, imagined ones included: an imagined evaluation
starts from the real first frame of an evaluation seed (`gymnast.envs.starts.evaluation_starts`)
and is judged by the run's reward. Its protocol matches `gymnast eval` (greedy chunks executed
open-loop, success at any step, the same horizon and seeds), so real-world figures are comparable
with it.

Every arm of an experiment starts from the same SFT policy and evaluates it on the same seeds
before its first step. Inside ``with shared_evaluations():`` an evaluation in a simulator (the
real world or the software one) of a policy with the same weights, on the same starts, env and
batch, is run once and its figures given to every later asker: greedy episodes of a deterministic
simulator are the same episodes (a test checks that the figures are identical). Each run still
counts the evaluation's interactions as its own, so the runs' counts stay comparable.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import torch
from gymnasium.vector import VectorEnv
from tqdm import tqdm

from gymnast.envs.engine import run_batch
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import REAL, EnvKind
from gymnast.envs.starts import Start, start_options
from gymnast.eval.stats import wilson_interval
from gymnast.reward.base import Reward
from gymnast.rl.rollout import Rollouts, collect_rollouts, score_groups


def verdicts(rollouts: Rollouts, scores: torch.Tensor, reward: Reward) -> torch.Tensor:
    """(R,) success as the run's env sees it: a simulator's own verdict, else a binary reward's
    (a judge's), else NaN (a continuous reward on imagined video says nothing about success)."""
    if rollouts.success is not None:
        return rollouts.success.float()
    if reward.binary:
        return scores.float()
    return torch.full_like(scores, float("nan"), dtype=torch.float32)


def evaluate_in_env(envs: EnvFactory, kind: EnvKind, policy, reward: Reward, starts: Sequence[Start],
                    prefix: str, progress: bool = False) -> dict[str, float]:
    """Greedy rollouts from `starts` in env `kind`; success with its 95% Wilson interval (a
    progress bar of the episodes with `progress`: hundreds of whole episodes take minutes).

    Returns ``{prefix}_episodes`` (judged), ``_interactions`` (actions taken, which are real
    interactions when `kind` declares ``real_interactions``) and, when any episode could be judged, ``_success``,
    ``_ci_low``, ``_ci_high`` and ``_success/<task>`` for every task.
    """
    key = _remembered.key(envs, kind, policy, starts)
    if key in _remembered.figures:
        return {f"{prefix}_{name}": value for name, value in _remembered.figures[key].items()}
    values = _evaluate_in_env(envs, kind, policy, reward, starts, progress)
    if key is not None:
        _remembered.figures[key] = values
    return {f"{prefix}_{name}": value for name, value in values.items()}


def _evaluate_in_env(envs: EnvFactory, kind: EnvKind, policy, reward: Reward, starts: Sequence[Start],
                     progress: bool) -> dict[str, float]:
    """`evaluate_in_env`'s figures, without the prefix."""
    env = envs.get(kind, evaluation_batch(len(starts), envs.batch))
    starts = taking_turns(starts)
    outcomes, interactions = [], 0
    bar = tqdm(total=len(starts), desc=f"evaluate {kind}", unit="ep", disable=not progress, leave=False)
    for first in range(0, len(starts), env.num_envs):
        batch = list(starts[first: first + env.num_envs])
        real = len(batch)
        batch += [batch[0]] * (env.num_envs - real)  # the env has a fixed size; extra rollouts are dropped
        # Where the env reports success (a simulator), no frame inside a chunk is read: none rendered.
        rollouts = collect_rollouts(env, policy, batch, 0.0, torch.Generator(), every_frame=not kind.reports_success)
        scores = score_groups(reward, rollouts, 1) if rollouts.success is None else torch.zeros(len(batch))
        outcomes.append(verdicts(rollouts, scores, reward)[:real])
        interactions += int(rollouts.lengths[:real].sum())
        bar.update(real)
    bar.close()
    success = torch.cat(outcomes)
    judged = success[torch.isfinite(success)]
    wins, total = int(judged.sum()), len(judged)
    values = {"episodes": total, "interactions": interactions}
    if total:  # nothing judged: a continuous reward on imagined video has no notion of success
        low, high = wilson_interval(wins, total)
        values |= {"success": wins / total, "ci_low": low, "ci_high": high}
        for task in dict.fromkeys(start.task for start in starts):
            mine = success[[i for i, start in enumerate(starts) if start.task == task]]
            values[f"success/{task}"] = torch.nanmean(mine).item()
    return values


def evaluation_batch(episodes: int, batch: int) -> int:
    """Rollouts per evaluation batch for `episodes` episodes in batches of at most `batch`: the
    fewest batches, of equal size. A vector env steps all its rollouts, so the padding of a last,
    partial batch would be simulated (or imagined) in full and thrown away: two evaluation
    episodes in a training batch of 8 would run four times as many, 50 in a batch of 64 over a
    quarter more (`evaluation_batch(50, 64)` is 50, `evaluation_batch(100, 64)` 50)."""
    if episodes < 1 or batch < 1:
        raise ValueError(f"an evaluation needs an episode and a batch of at least one, got {episodes} and {batch}")
    batches = math.ceil(episodes / batch)
    return math.ceil(episodes / batches)


def taking_turns(starts: Sequence[Start]) -> list[Start]:
    """`starts` reordered so that their tasks take turns (first of each task, then second...), as
    training batches draw them (`gymnast.envs.starts.StartSampler`): a simulator process then runs
    an evaluation batch on the scenes its training batches built, instead of building (and, two
    cameras at 55 MB a scene, holding) as many again for runs of one task."""
    by_task: dict[str, list[Start]] = {}
    for start in starts:
        by_task.setdefault(start.task, []).append(start)
    turns = itertools.zip_longest(*by_task.values())
    return [start for turn in turns for start in turn if start is not None]


class _Remembered:
    """The simulator evaluations of a `shared_evaluations` block, by what decides their episodes."""

    def __init__(self) -> None:
        self.active = False
        self.figures: dict[tuple, dict[str, float]] = {}

    def key(self, envs: EnvFactory, kind: EnvKind, policy, starts: Sequence[Start]) -> tuple | None:
        """What decides a greedy evaluation's episodes; None outside a block, in imagination (a
        world model's episodes also depend on its reward and weights, which change with Dyna) and
        for a policy that is not one module of weights (a wrapper that adds noise acts otherwise)."""
        if not self.active or kind.imagined or not isinstance(policy, torch.nn.Module):
            return None
        scenes = tuple((s.task, s.seed, s.instruction, s.prefix.tobytes()) for s in starts)
        return (kind.name, envs.config, envs.gap, envs.chunk_size, evaluation_batch(len(starts), envs.batch), scenes,
                policy_fingerprint(policy))


_remembered = _Remembered()


def policy_fingerprint(policy) -> str:
    """A digest of the policy's weights and buffers: equal for policies that act alike."""
    digest = hashlib.sha256(type(policy).__qualname__.encode())
    for name, tensor in policy.state_dict().items():
        digest.update(name.encode())
        digest.update(tensor.detach().cpu().contiguous().view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


@contextlib.contextmanager
def shared_evaluations() -> Iterator[None]:
    """Within the block, an evaluation in a simulator repeated with the same policy weights, starts,
    env and batch gives the first one's figures without running again (nested blocks share the outer one's)."""
    if _remembered.active:
        yield
        return
    _remembered.active = True
    try:
        yield
    finally:
        _remembered.active, _remembered.figures = False, {}


@dataclass(frozen=True)
class Replay:
    """R rollouts' actions replayed in a simulator (`replay_actions`).

    Attributes:
        success: (R,) bool whether the simulator reported success at any step of the replay.
        frames: (R, T + 1, H, W, 3) uint8 the start frame, then one frame per action, the frame at
            a rollout's end repeating after it (as in `Rollouts.frames`).
        success_by_step: (R, T) bool success at any step up to the end of the chunk holding action
            t (the simulator reports success once per chunk); False after the replay's end.
        rewards: (R, T) float32 the simulator's reward for each action (NaN after the replay's end).
        interactions: actions the simulator executed (real interactions in the real world), those
            replayed to restore keyframe starts (their prefixes) included.
    """

    success: torch.Tensor | None
    frames: torch.Tensor
    success_by_step: torch.Tensor | None
    rewards: torch.Tensor | None
    interactions: int


def replay_actions(env: VectorEnv, starts: Sequence[Start], actions: torch.Tensor, lengths: torch.Tensor,
                   every_frame: bool = True) -> Replay:
    """Replays R rollouts' actions, action for action, in a simulator (or a world model) from the
    same start states.

    A world model reports no outcome: its replay (a re-imagining of the actions from the same start
    frames) has frames only, ``success``, ``success_by_step`` and ``rewards`` None, and
    ``interactions`` counts imagined actions.

    The env steps whole chunks, so the chunk holding a rollout's last action is executed in full
    (with the zero actions that follow its end); a replay's outcome is read at the end of that
    chunk. An env that does not terminate at success (``EnvConfig.terminate_on_success=False``)
    executes every action, so every frame of the rollout has a replayed counterpart; it also keeps
    stepping (with zero actions) the replays that ended before the longest one, since a vector env
    steps all its episodes together.

    Args:
        env: a `SimVectorEnv` or `BatchedImaginedEnv` (or one with their contract) with ``num_envs == R``.
        starts: the R start states (their task and seed fix the scene).
        actions: (R, T, A) float32 the actions to replay (0 after each rollout's end).
        lengths: (R,) int64 actions each rollout executed.
        every_frame: False when only the outcome and the frames the policy would read are wanted: a
            simulator renders each chunk's last frame alone, and the frames inside a chunk repeat it
            (rendering is most of a simulator step's cost).
    """
    count, steps = actions.shape[:2]
    if env.num_envs != count or len(starts) != count or lengths.shape != (count,):
        raise ValueError(f"the env runs {env.num_envs} episodes; got {len(starts)} starts, actions "
                         f"{tuple(actions.shape)} and lengths {tuple(lengths.shape)}")
    chunk = env.single_action_space.shape[0]
    last_chunk = (lengths - 1).clamp(min=0) // chunk  # (R,) the chunk that ends each replay
    calls = int(last_chunk.max()) + 1
    planned = torch.zeros(count, calls * chunk, actions.shape[2])  # zero actions after the end
    planned[:, : min(steps, calls * chunk)] = actions[:, : calls * chunk].float()
    plan = iter(planned.split(chunk, dim=1))  # (R, K, A) each
    frames, by_chunk, rewards = [], [], []
    interactions = sum(len(start.prefix) for start in starts)  # restoring a keyframe takes real actions
    success = torch.zeros(count, dtype=torch.bool)
    reports = True  # a world model reports no outcome
    for index, result in enumerate(run_batch(env, lambda images, instructions, states: next(plan).numpy(),
                                             start_options(starts) | {"every_frame": every_frame}, seed=0,
                                             max_calls=calls)):
        if not frames:
            frames.append(torch.from_numpy(result.observation)[:, None])  # (R, 1, H, W, 3) the start frame
        frames.append(torch.from_numpy(result.frames))  # (R, K, H, W, 3)
        interactions += int(result.executed.sum())
        reports = result.success is not None
        if reports:
            success = torch.where(last_chunk >= index, torch.from_numpy(result.success), success)  # only accumulates
            by_chunk.append(success[:, None].expand(-1, chunk))  # (R, K)
            rewards.append(torch.from_numpy(result.rewards))  # (R, K) NaN where not executed
    video = torch.cat(frames, dim=1)[:, : steps + 1]  # (R, <= T + 1, H, W, 3)
    ends = lengths.clamp(max=video.shape[1] - 1)  # (R,) the frame at each rollout's end
    index = torch.minimum(torch.arange(steps + 1)[None], ends[:, None])  # (R, T + 1): the end frame repeats
    video = video[torch.arange(count)[:, None], index]
    if not reports:
        return Replay(None, video, None, None, interactions)
    after_end = torch.arange(steps)[None] >= lengths[:, None]  # (R, T)
    success_by_step = _to_steps(torch.cat(by_chunk, dim=1), steps, False) & ~after_end
    step_rewards = _to_steps(torch.cat(rewards, dim=1), steps, float("nan")).masked_fill(after_end, float("nan"))
    return Replay(success, video, success_by_step, step_rewards, interactions)


def _to_steps(values: torch.Tensor, steps: int, fill) -> torch.Tensor:
    """(R, calls * K) per-action values cut or padded with `fill` to (R, steps)."""
    if values.shape[1] >= steps:
        return values[:, :steps]
    return torch.cat([values, torch.full((len(values), steps - values.shape[1]), fill, dtype=values.dtype)], dim=1)


def watch_hacking(envs: EnvFactory, rollouts: Rollouts, scores: torch.Tensor, verdict: torch.Tensor,
                  count: int) -> dict[str, float]:
    """Replays the actions of `count` rollouts in the real world from the same start states and
    compares the real outcome with what the rollouts were trained on.

    A rollout that ended early (a simulator's success) is judged in the real world at the end of
    the chunk holding its last action.

    Returns ``eval/watch_real_success`` and ``eval/watch_interactions`` (real actions taken);
    where the rollouts have verdicts (binary rewards, simulators), ``eval/watch_agreement`` (share
    whose real outcome equals the verdict), ``eval/watch_imagined_success`` and
    ``eval/watch_false_success`` (the share judged successful that failed in the real world:
    reward hacking, or judge error); and where replays both succeeded and failed,
    ``eval/watch_reward_gap``: mean reward of real successes minus that of real failures (a
    continuous reward that tracks the real outcome has a positive gap).
    """
    count = min(count, len(rollouts.starts))
    pick = torch.linspace(0, len(rollouts.starts) - 1, count).round().long()
    chosen = rollouts.select(pick)
    replay = replay_actions(envs.get(REAL, count), chosen.starts, chosen.actions, chosen.lengths,
                            every_frame=False)  # the outcome alone is read
    real, interactions = replay.success, replay.interactions
    values = {"eval/watch_real_success": real.float().mean().item(), "eval/watch_interactions": interactions}
    judged = torch.isfinite(verdict[pick])
    if judged.any():
        imagined, outcome = verdict[pick][judged] > 0.5, real[judged]
        values |= {"eval/watch_agreement": (imagined == outcome).float().mean().item(),
                   "eval/watch_imagined_success": imagined.float().mean().item(),
                   "eval/watch_false_success": (imagined & ~outcome).float().sum().item() / max(1, int(imagined.sum()))}
    picked_scores = scores[pick]
    if real.any() and (~real).any():
        values["eval/watch_reward_gap"] = (picked_scores[real].nanmean() - picked_scores[~real].nanmean()).item()
    return values
