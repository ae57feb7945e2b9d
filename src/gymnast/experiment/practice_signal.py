"""Does practice in imagination push the policy where the real world would? The GRPO signal of a
world model and a reward, held against the real outcome of the same actions.

Legend: B start states (groups), G rollouts per start, R = B x G rollouts, T actions, H/W image size.

Verdict agreement (`gymnast imagination`) mixes two errors that matter very differently to RL.
Imagination can be wrong about *how often* a policy succeeds, a calibration error that GRPO does
not see, since it normalises rewards within each group; or wrong about *which* of a group's
rollouts succeed, a ranking error that sends the update the wrong way. GRPO's step is the sum of
each rollout's log-probability gradient weighted by its group-normalised advantage, so a step in
imagination is a step forward in the real world as far as the imagined advantages agree with the
advantages the real outcomes would have given the same rollouts.

For B real starts the policy samples G rollouts each at the rollout temperature in the world
model, closed loop on the imagined frames; the same actions are replayed in the real world from
the same start, and each rollout's real outcome at horizon h is read two ways: success within its
first h actions, and the real dense return of those h actions (Meta-World's reward, as
`dense_return` scores it). The starts are fresh scenes' first frames (new data seeds, as `gymnast
rl --fresh-scenes` draws them), or keyframes of a dataset's held-out episodes
(`gymnast.data.keyframes`: anywhere in an episode, restored in the real world by replaying the
actions that led there), for segments as short as practice from keyframes runs them. For a
segment the dense return is the outcome to hold imagination against: a segment of 8-40 actions
from the middle of an episode often cannot reach success, and the dense reward is the real signal
that taught RL in the real world here (results/rl/reach_real); success is reported beside it. Every *readout* scores the imagined rollouts: the reward's own
score (a judge's verdict, a progress judge's degree) and, for a per-frame 0/1 judge, its
probability (the largest over the frames, a continuous score), each on the video cut after h actions;
a grounded world model's reward head (`gymnast.reward.state_reward`) is read from the state it
imagines under the same actions, as its predicted return and its success verdict. Two references are read out too: the
same readouts of the real replay's video, which separates the reward's own error from the world
model's (the judge sees what really happened), and the real world's dense reward of the replay
(Meta-World's, with which RL in the real world did learn, results/rl/reach_real), a signal known
to teach. Per readout and horizon:

- ``advantage_correlation``: sum(A_read * A_real) / sqrt(sum(A_read^2) * sum(A_real^2)) over the R
  rollouts, A being GRPO's group advantage (`gymnast.rl.grpo.group_advantages`, 0 in a group
  without spread) and A_real that of the real success: 1 when every group is ranked as reality
  ranks it, 0 when the updates are noise with respect to the real outcome, negative when they
  point away from it; with a 95% interval from resampling the groups.
- ``return_correlation`` (with its interval): the same against the real dense return's advantages.
- ``reinforced_real_success`` and ``discouraged_real_success``: the real success of the rollouts GRPO
  would make more likely (positive advantage) and less likely (negative).
- ``signal_groups``: the share of groups the readout ranks at all (the others give no gradient).
- for a binary readout, ``agreement`` with the real outcome and ``false_success`` (the share of
  its successes that fail in the real world).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.data.keyframes import KeyframeConfig
from gymnast.envs.kinds import IMAGINED, REAL
from gymnast.envs.starts import Start, scene_starts
from gymnast.envs.tasks import DATA_SEEDS, resolve_tasks
from gymnast.envs.workers import parse_runner
from gymnast.experiment.signal_report import (ON_REAL_VIDEO, PROBABILITY, REAL_DENSE, SCORE, VERDICT, format_signal,
                                             signal_table)
from gymnast.policy.base import Policy
from gymnast.reward.base import Reward, RewardContext
from gymnast.reward.sim import META_WORLD_MAX_STEP_REWARD
from gymnast.reward.spec import RewardSpec
from gymnast.rl.rollout import reward_context
from gymnast.utils.atomic import write_bytes, write_json
from gymnast.world_model.base import WorldModel
from gymnast.world_model.views import model_cameras, replay_cameras

logger = logging.getLogger(__name__)

WEAK_TASKS = "reach-v3,push-v3,pick-place-v3,peg-insert-side-v3"
"""The tasks the SFT policy fails most (10-24% real success), where practice has most to gain."""


def batch_for(group_size: int) -> int:
    """Rollouts stepped together for groups of `group_size`: about 64, in whole groups."""
    return group_size * max(1, 64 // group_size)


@dataclass(frozen=True)
class SignalConfig:
    """Which scenes, how many rollouts, and the horizons read out."""

    tasks: str = WEAK_TASKS
    """Task names and/or task sets (mt10, mt50), comma-separated."""
    starts_per_task: int = 8
    """Starts (groups) per task."""
    task_starts: dict[str, int] = field(default_factory=dict)
    """Starts for the tasks named here instead of `starts_per_task`: more where few groups have a
    spread of real success (the weak tasks: 4 starts a task gave 16 groups there, too few to rank)."""
    data: str = ""
    """Dataset whose held-out episodes give keyframe starts (`keyframes`); empty: fresh scenes' first frames."""
    keyframes: str = "uniform"
    """How keyframes are drawn from `data`'s episodes: first, uniform, near_success or failures
    (`gymnast.data.keyframes`); unused without `data`."""
    heldout_fraction: float = 0.1
    """Share of `data`'s scenes the models held out (their training split), the only ones keyframes
    come from; 0: every episode (a dataset they never trained on, e.g. the policy's own rollouts)."""
    group_size: int = 8
    """Rollouts G per scene, as GRPO samples them."""
    temperature: float = 1.0
    """The policy's sampling temperature (the rollout temperature of `gymnast rl`)."""
    horizons: tuple[int, ...] = (50, 100, 150)
    """Horizons h read out (the video cut after h actions, the replay's success by then); the
    largest is the rollouts' horizon. Multiples of the policy's chunk are exact: the simulator
    reports success once per chunk."""
    batch: int = 64
    """Rollouts stepped together (a multiple of the group size)."""
    workers: int = 2
    """Simulator processes for the real-world replays."""
    runner: str = "local"
    """Where the simulator processes run: local, ray or ray:ADDRESS (see `gymnast eval --help`)."""
    seed: int = 0
    """Seed of the scenes drawn and of the policy's samples."""

    def __post_init__(self) -> None:
        for name in ("starts_per_task", "group_size", "batch", "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"SignalConfig.{name} must be at least 1, got {getattr(self, name)}")
        for task, count in self.task_starts.items():
            if count < 1:
                raise ValueError(f"SignalConfig.task_starts[{task!r}] must be at least 1, got {count}")
        strangers = sorted(set(self.task_starts) - set(resolve_tasks(self.tasks)))
        if strangers:
            raise ValueError(f"SignalConfig.task_starts names {strangers}, not among its tasks ({self.tasks})")
        if self.group_size < 2:
            raise ValueError(f"SignalConfig.group_size must be at least 2 (a group of one ranks nothing), got {self.group_size}")
        if self.batch % self.group_size:
            raise ValueError(f"SignalConfig.batch ({self.batch}) must be a multiple of group_size ({self.group_size})")
        if self.temperature <= 0:
            raise ValueError(f"SignalConfig.temperature must be > 0 (GRPO samples), got {self.temperature}")
        if not self.horizons or min(self.horizons) < 1:
            raise ValueError(f"SignalConfig.horizons must be positive, got {self.horizons}")
        if self.data:
            KeyframeConfig(sampling=self.keyframes)  # fails here, naming the setting
        if not 0 <= self.heldout_fraction < 1:
            raise ValueError(f"SignalConfig.heldout_fraction must be in [0, 1), got {self.heldout_fraction}")
        parse_runner(self.runner)

    @property
    def horizon(self) -> int:
        return max(self.horizons)

    def starts_for(self, task: str) -> int:
        """Starts (groups) of `task`."""
        return self.task_starts.get(task, self.starts_per_task)


def measure_signal(policy: Policy, world_model: WorldModel, reward: Reward, config: SignalConfig,
                   out: Path | None = None, progress: bool = True, labels: dict[str, str] | None = None,
                   robot_state=None) -> dict:
    """Measures the GRPO signal of imagination under `policy` (see the module docstring).

    Args:
        policy: the policy practice would start from; sampled at ``config.temperature``.
        world_model: imagines the rollouts.
        reward: scores the imagined videos (a learned judge also gives its probability).
        config: scenes, group size, temperature, horizons and batching.
        out: directory for signal.json and signal.md (None: nothing written).
        progress: show a progress bar over the batches.
        labels: what the objects are (e.g. run paths), recorded in the settings.
        robot_state: for a policy that reads the robot's state, what imagines it beside the world
            model (`gymnast.world_model.robot_state.robot_state_in_imagination`).

    Returns:
        signal.json's content: ``settings``; ``readouts`` (a row per readout and horizon, see
        `signal_table`); ``per_task`` (the same rows for each task's groups); ``interactions`` (real
        actions of the replays); ``seconds``; ``rollouts`` (one record per rollout: task, seed,
        group, the real outcome and every readout by horizon).
    """
    from gymnast.envs.factory import EnvFactory
    from gymnast.rl.evaluate import replay_actions
    from gymnast.rl.rollout import collect_rollouts

    began = time.perf_counter()
    tasks = resolve_tasks(config.tasks)
    env_config = EnvConfig(image_size=world_model.image_size, horizon=config.horizon, cameras=replay_cameras(world_model))
    starts = (heldout_keyframes(Path(config.data), tasks, config, world_model.image_size, model_cameras(world_model))
              if config.data
              else fresh_starts({task: config.starts_for(task) for task in tasks}, env_config, config.seed))
    rollout_starts = [start for start in starts for _ in range(config.group_size)]  # groups are contiguous
    size = min(config.batch, len(rollout_starts))
    envs = EnvFactory(IMAGINED, policy.chunk_size, env_config, "none", config.workers, world_model,
                      robot_state=robot_state)
    # Replays go on after success, so every horizon's outcome is read from the same replay.
    replays = EnvFactory(REAL, policy.chunk_size, dataclasses.replace(env_config, terminate_on_success=False), "none",
                         config.workers, runner=config.runner)
    generator = torch.Generator().manual_seed(config.seed)
    records, seconds, interactions = [], dict.fromkeys(("imagine", "score", "replay"), 0.0), 0

    def timed(name: str, work):
        clock = time.perf_counter()
        result = work()
        seconds[name] += time.perf_counter() - clock
        return result

    try:
        for first in tqdm(range(0, len(rollout_starts), size), desc="signal", unit="batch", disable=not progress):
            batch = rollout_starts[first: first + size]
            imagined = timed("imagine", lambda: collect_rollouts(envs.get(IMAGINED, len(batch)), policy, batch,
                                                                 config.temperature, generator, config.seed))
            readouts = timed("score", lambda: read_out(reward, imagined.frames, imagined.instructions, config.horizons,
                                                       reward_context(imagined)))
            replay = timed("replay", lambda: replay_actions(replays.get(REAL, len(batch)), imagined.starts,
                                                            imagined.actions, imagined.lengths))
            interactions += replay.interactions
            if not reward.needs.start_state:  # a reward of the video: read it on the real video too
                on_real = timed("score", lambda: read_out(reward, replay.frames, imagined.instructions, config.horizons))
                readouts |= {f"{name}{ON_REAL_VIDEO}": values for name, values in on_real.items()}
            readouts[REAL_DENSE] = {h: dense_return(replay.rewards[:, :h], replay.success_by_step[:, :h])
                                    for h in config.horizons}
            for i, start in enumerate(batch):
                records.append({"task": start.task, "seed": start.seed, "keyframe": len(start.prefix),
                                "group": (first + i) // config.group_size,
                                "real": {str(h): bool(replay.success_by_step[i, h - 1]) for h in config.horizons},
                                "real_return": {str(h): float(readouts[REAL_DENSE][h][i]) for h in config.horizons},
                                "readouts": {name: {str(h): float(values[h][i]) for h in config.horizons}
                                             for name, values in readouts.items()}})
    finally:
        envs.close()
        replays.close()
    seconds["total"] = time.perf_counter() - began
    binary = {name: (name in (SCORE, SCORE + ON_REAL_VIDEO) and reward.binary) or name == VERDICT
              for name in records[0]["readouts"]}
    report = {
        "settings": {**dataclasses.asdict(config), **(labels or {}), "task_list": list(tasks),
                     "reward_type": type(reward).__name__, "policy_type": type(policy).__name__,
                     "binary_readouts": [name for name, is_binary in binary.items() if is_binary]},
        "readouts": signal_table(records, config.horizons, config.group_size, binary),
        "per_task": {task: signal_table([r for r in records if r["task"] == task], config.horizons, config.group_size, binary)
                     for task in tasks},
        "interactions": interactions,
        "seconds": seconds,
        "rollouts": records,
    }
    longest = next(row for row in report["readouts"] if row["readout"] == SCORE and row["horizon"] == config.horizon)
    logger.info("signal: advantage correlation %s over %d rollouts at horizon %d", longest["advantage_correlation"],
                len(records), config.horizon)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "signal.json", report)
        write_bytes(out / "signal.md", format_signal(report).encode())
    return report


def fresh_starts(counts: dict[str, int], config: EnvConfig, seed: int) -> list[Start]:
    """`counts[task]` new scenes of each task from random data seeds (drawn from `seed`, none twice),
    as `gymnast rl --fresh-scenes` starts its groups: real first frames, rendered by a reset (no
    interaction)."""
    draw = np.random.default_rng(seed)
    seeds = iter(draw.choice(DATA_SEEDS.stop - DATA_SEEDS.start, size=sum(counts.values()), replace=False)
                 + DATA_SEEDS.start)
    return scene_starts([(task, int(next(seeds))) for task, count in counts.items() for _ in range(count)], config)


def heldout_keyframes(data: Path, tasks: Sequence[str], config: SignalConfig, image_size: int,
                      cameras: Sequence[str] = ()) -> list[Start]:
    """`config.starts_for(task)` keyframes of each task from the episodes of `data`'s held-out scenes
    (`config.heldout_fraction`, the world models' split: they never trained on them) recorded in the real world, drawn by
    `config.keyframes` from `config.seed`; the frames fitted to `image_size` as the models were
    trained, the views of several `cameras` side by side (default: the dataset's first). A task with
    fewer held-out episodes than starts lends its other episodes (with a warning; `start_episodes`):
    a dataset too small to hold scenes out measures the models on what they trained on.

    Raises:
        ValueError: a task has no real episode in `data` (that fits the sampling).
    """
    from gymnast.data.keyframes import KeyframeConfig, dataset_keyframes
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.world_model.data import is_heldout

    dataset = EpisodeDataset(data, cameras=cameras or None)
    if dataset.image_shape[:2] != (image_size, image_size):
        dataset = dataset.fitted(image_size, "resize")
    draw, starts = np.random.default_rng(config.seed), []
    keyframes = KeyframeConfig(sampling=config.keyframes, horizon=config.horizon)
    for task in tasks:
        episodes = [i for i, info in enumerate(dataset.episodes) if info.task == task and info.env_variant == "real"
                    and not (config.keyframes == "failures" and info.success)]
        if not episodes:
            raise ValueError(f"{data} has no real episode of {task} to take {config.keyframes} keyframes from")
        heldout = [i for i in episodes if not config.heldout_fraction or is_heldout(dataset.episodes[i],
                                                                                    config.heldout_fraction)]
        trained = sorted(set(episodes) - set(heldout))
        chosen = start_episodes(heldout, trained, config.starts_for(task), draw)
        lent = sum(i in trained for i in chosen)
        if lent:
            logger.warning("%s: %d held-out episode(s) of %s for %d starts; %d start(s) come from episodes the "
                           "models trained on", data, len(heldout), task, config.starts_for(task), lent)
        # One keyframe per pick: an episode picked twice gives two keyframes (the same one for `first`).
        starts += [dataset_keyframes(dataset, [int(i)], keyframes, seed=config.seed + n)[0] for n, i in enumerate(chosen)]
    return starts


def start_episodes(heldout: Sequence[int], trained: Sequence[int], count: int, draw: np.random.Generator) -> list[int]:
    """`count` episodes to take starts from, each at most once while there are enough: the held-out
    ones first, then (too few held out) episodes the models trained on, and only when the task has
    fewer than `count` episodes in all, repeats. Groups from one scene are not independent, so a
    repeated scene would narrow the intervals without adding evidence."""
    chosen = [int(i) for i in draw.permutation(np.asarray(heldout, dtype=np.int64))[:count]]
    chosen += [int(i) for i in draw.permutation(np.asarray(trained, dtype=np.int64))[: count - len(chosen)]]
    if len(chosen) < count:
        chosen += [int(i) for i in draw.choice(chosen, size=count - len(chosen))]
    return chosen


def read_out(reward: Reward, frames: torch.Tensor, instructions: Sequence[str], horizons: Sequence[int],
             context: RewardContext | None = None) -> dict[str, dict[int, torch.Tensor]]:
    """Every readout of (R, T + 1, H, W, 3) videos cut after each horizon's h actions: ``score`` (the
    reward as RL reads it) and, for a per-frame 0/1 judge, ``probability``, or for a grounded world
    model's reward head, its ``verdict``; (R,) each.

    A per-frame judge, or a state model, is run once for all horizons. A reward reads only the video
    (a judge), or the start state and the (R, T, A) actions of `context` (a state model's head); one
    that needs a reference or a simulator cannot be read out.
    """
    if reward.needs.start_state:
        if context is None or context.actions is None:
            raise ValueError(f"{type(reward).__name__} reads the start states and the actions: pass their context")
        read = reward.read(instructions, context, horizons)  # one imagination serves every horizon
        return {SCORE: {h: score.float() for h, (score, _) in read.items()},
                VERDICT: {h: verdict for h, (_, verdict) in read.items()}}
    per_frame = getattr(reward, "frame_probabilities", None)
    if per_frame is None:  # a reward of whole videos: score each cut
        return {SCORE: {h: reward.score(frames[:, : h + 1], instructions, RewardContext()).float() for h in horizons}}
    frame_values = per_frame(frames, instructions)  # (R, T + 1): one pass serves every horizon
    if not reward.binary:  # a progress judge: the mean over the frames after the first, as its score is
        return {SCORE: {h: frame_values[:, 1: h + 1].mean(dim=1) for h in horizons}}
    best = {h: reward.video_probability(frame_values[:, : h + 1]) for h in horizons}  # as FrameJudge.probability
    return {SCORE: {h: (p >= reward.config.threshold).float() for h, p in best.items()},  # as ThresholdJudge.score
            PROBABILITY: best}


def dense_return(rewards: torch.Tensor, success_by_step: torch.Tensor) -> torch.Tensor:
    """(R,) Meta-World's dense reward as `gymnast.reward.sim.SimDense` scores a rollout, for (R, h)
    per-step rewards and success of a replay that goes on after success: from the success on, each
    step counts as the maximum reward, as the early-ending episode of RL in the real world does."""
    held = torch.where(success_by_step, torch.full_like(rewards, META_WORLD_MAX_STEP_REWARD), rewards)
    return torch.nanmean(held.float(), dim=1).nan_to_num(0.0) / META_WORLD_MAX_STEP_REWARD


def practice_of(run: Path) -> tuple[dict[str, str], dict]:
    """What the RL run in `run` practises with, as `measure_signal_runs` takes it: its policy, world
    model and reward (``policy``, ``wm``, ``reward``), and the `SignalConfig` settings of its
    practice: tasks, starts (its dataset's keyframes, drawn as it draws them), horizon, group size,
    temperature and seed. The signal is then measured on the practice the run does, not on a
    neighbour of it.

    Raises:
        ValueError: the run does not practise in imagination (nothing to measure).
    """
    from gymnast.rl.config import saved_rl_settings
    from gymnast.utils.settings import saved_settings

    spec, rl = saved_rl_settings(run)
    if not spec.env.imagined:
        raise ValueError(f"{run} practises in the {spec.env.name} world, not in imagination: there is no imagined "
                         "signal to hold against the real one")
    # Without a dataset of its own, RL starts from the one the policy was trained on.
    data = spec.data or saved_settings(Path(spec.policy)).get("data") or ""
    settings = {"tasks": rl.tasks, "group_size": rl.group_size, "temperature": rl.temperature,
                "horizons": (rl.horizon,), "batch": batch_for(rl.group_size), "seed": rl.seed,
                "data": str(data), "keyframes": rl.keyframes}
    inputs = {"policy": spec.policy, "wm": str(spec.wm), "reward": str(spec.reward)}
    if spec.robot_state is not None:
        inputs["robot_state"] = str(spec.robot_state)
    return inputs, settings


def measure_signal_runs(policy: str | Path, wm: str | Path, reward: RewardSpec, config: SignalConfig,
                        out: Path | None = None, progress: bool = True, robot_state: str | Path | None = None) -> dict:
    """`measure_signal` of saved runs: a policy run, a world-model run and a reward spec that reads
    only the video (``judge:RUN`` or ``vlm:MODEL@BASE_URL``) or a grounded world model's reward head
    (``state:RUN``), see `gymnast.reward.spec`; and for a policy that reads the robot's state, the
    state model run that imagines it (``--robot-state``)."""
    from gymnast.experiment.imagination import measured_policy
    from gymnast.reward.select import make_reward
    from gymnast.world_model.base import load_world_model

    if reward.kind not in ("judge", "vlm", "state"):  # said before anything loads
        raise ValueError(f"--reward {reward} reads more than the imagined video; rl-signal reads a judge "
                         "(judge:RUN or vlm:MODEL@BASE_URL) or a state model's reward head (state:RUN)")
    world_model = load_world_model(wm)
    judge = make_reward(reward, world_model)
    loaded, state, labels = measured_policy(policy, world_model, wm, reward, judge, robot_state)
    return measure_signal(loaded, world_model, judge, config, out, progress, labels, state)
