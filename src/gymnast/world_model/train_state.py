"""`gymnast train-state`: fit the grounded state model (`gymnast.world_model.state_model`) to a
dataset's recorded states, rewards and success flags, and measure it on the held-out scenes.

Legend: N episodes, B batch, L unrolled steps, T longest episode, S state dimensions, A action
dimensions, E instruction embedding.

Each step draws B windows of L steps from random episodes and times, imagines the L states open
loop from the window's real first state under its real actions, and minimises, over the steps
inside the episode: the squared error of every imagined state (in normalised units), and of the
reward head's reward and success on both the imagined and the recorded states (the recorded ones
teach the head what the task rewards; the imagined ones, what it should say of a drifted state).
Backpropagating through the unrolled steps teaches the dynamics to correct its own drift, as the
video model's training does.

`evaluate_state_model` measures what practice relies on, on scenes the model never trained on:
how far the imagined hand and object end from the real ones after h actions (centimetres, against
the linear baseline of docs/world_model.md), and how well the imagined rewards and success agree
with the recorded ones.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.data.schema import EXTERNAL
from gymnast.policy.text import InstructionEncoder
from gymnast.utils.atomic import write_json
from gymnast.utils.checkpoint import begin_training, resolve_checkpoint, save_training
from gymnast.utils.optim import gradient_step, warmup_cosine
from gymnast.utils.trackers import TrackerNames
from gymnast.world_model.data import split_episodes
from gymnast.world_model.metrics import pearson
from gymnast.world_model.state_model import REWARD_SCALE, StateModel, StateModelConfig, load_state_model

logger = logging.getLogger(__name__)

HAND, OBJECT = slice(0, 3), slice(4, 7)
"""Where Meta-World's environment state keeps the hand's and the first object's position (metres)."""


@dataclass(frozen=True)
class StateTrainConfig:
    """State-model training settings."""

    steps: int = 4000
    """Optimiser steps."""
    batch_size: int = 256
    """Windows B per step."""
    unroll: int = 16
    """L: steps imagined open loop per window (what the model learns to stay right over)."""
    lr: float = 1e-3
    """Peak learning rate (AdamW, warm-up then cosine decay)."""
    hidden: int = 256
    """Width of the networks."""
    last_action: bool = True
    """Condition each step on the action before it too (`StateModelConfig.last_action`)."""
    extra_data: tuple[Path, ...] = ()
    """More datasets to train on (the same state and actions), e.g. the policy's own rollouts, split
    by the same scene hash."""
    keys: FeatureKeys = FeatureKeys()
    """Which dataset features are the actions and the states (--action-key, --state-key); saved with the run."""
    ridge: float = 1e-4
    """Start the dynamics' linear path at the ridge-regularised least-squares fit of the recorded
    steps, with this penalty per input (0: start it at zero)."""
    heldout_fraction: float = 0.1
    """Share of the scenes kept out of training for the evaluation (the world model's split)."""
    checkpoint_every: int = 1000
    """Steps between checkpoints (and at the end)."""
    seed: int = 0
    """Seed of the initial weights and of the windows drawn."""
    tracker: TrackerNames = ()
    """Where the run logs besides RUN/metrics.jsonl: none, or any of tensorboard and wandb,
    comma-separated (gymnast.utils.trackers)."""
    init: Path | None = None
    """Start from the weights of this state-model run or checkpoint (fine-tuning, e.g. on the
    policy's newest rollouts between rounds of practice) instead of a fresh model: its architecture
    and its normalisation of states and actions are kept, so `hidden`, `last_action` and `ridge` are
    its own. The optimiser and the learning-rate schedule start afresh."""

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "unroll", "hidden", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"StateTrainConfig.{name} must be at least 1, got {getattr(self, name)}")


@dataclass(frozen=True)
class EpisodeTensors:
    """N episodes padded to the longest (T actions), for drawing windows in one indexing operation.

    Attributes:
        states: (N, T + 1, S) recorded states (padded by repeating the last).
        actions: (N, T, A); rewards (N, T) in [0, 1]; success (N, T) float.
        lengths: (N,) actions per episode.
        embedding: (N, E) the instruction's embedding.
        tasks: the N task names.
    """

    states: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    success: torch.Tensor
    lengths: torch.Tensor
    embedding: torch.Tensor
    tasks: tuple[str, ...]

    def windows(self, index: torch.Tensor, starts: torch.Tensor, steps: int) -> tuple[torch.Tensor, ...]:
        """Windows of `steps` actions from (B,) episodes at (B,) start times: (B, S) first state,
        (B, L, A) actions, (B, L, S) next states, (B, L) rewards and success, (B, L) bool inside,
        and (B, A) the action before the window (zeros at an episode's start)."""
        times = starts[:, None] + torch.arange(steps)  # (B, L)
        inside = times < self.lengths[index, None]
        times = times.clamp(max=self.actions.shape[1] - 1)
        rows = index[:, None].expand_as(times)
        before = torch.where((starts > 0)[:, None], self.actions[index, (starts - 1).clamp(min=0)], 0.0)
        return (self.states[index, starts], self.actions[rows, times], self.states[rows, times + 1],
                self.rewards[rows, times], self.success[rows, times], inside, before)


def episode_tensors(dataset: EpisodeDataset | list[tuple[EpisodeDataset, list[int]]], episodes: list[int] | None,
                    encoder: InstructionEncoder, progress: bool = False) -> EpisodeTensors:
    """The given episodes of a dataset (or of several: a list of (dataset, episodes) and
    `episodes` None) as padded tensors (state: the environment state where recorded, else
    ``observation.state``).

    Raises:
        ValueError: no episodes, or an episode without a state.
    """
    sources = dataset if episodes is None else [(dataset, episodes)]
    if not any(chosen for _, chosen in sources):
        raise ValueError(f"{', '.join(str(d.root) for d, _ in sources)}: no episodes to train the state model on")
    pairs = [(data, i) for data, chosen in sources for i in chosen]
    loaded = [data.load(i) for data, i in tqdm(pairs, desc="load", unit="ep", disable=not progress)]
    longest = max(len(e.actions) for e in loaded)

    def pad(values: np.ndarray, length: int) -> np.ndarray:
        return np.concatenate([values, np.repeat(values[-1:], length - len(values), axis=0)]) if len(values) < length else values

    states = []
    for (data, i), episode in zip(pairs, loaded):
        state = episode.full_states
        if state.shape[1] == 0:
            raise ValueError(f"{data.root}: episode {i} records no observation.state; the state model learns from it")
        if states and state.shape[1] != states[0].shape[1]:
            raise ValueError(f"{data.root}: episode {i} has a state of {state.shape[1]} numbers, the episodes before "
                             f"it {states[0].shape[1]}; datasets trained on together need the same state")
        states.append(pad(state, longest + 1))
    return EpisodeTensors(
        states=torch.from_numpy(np.stack(states)).float(),
        actions=torch.from_numpy(np.stack([pad(e.actions, longest) for e in loaded])).float(),
        rewards=torch.from_numpy(np.stack([pad(e.rewards, longest) for e in loaded])).float() / REWARD_SCALE,
        success=torch.from_numpy(np.stack([pad(e.successes, longest) for e in loaded])).float(),
        lengths=torch.tensor([len(e.actions) for e in loaded]),
        embedding=encoder([e.info.instruction for e in loaded]),
        tasks=tuple(e.info.task for e in loaded),
    )


def state_loss(model: StateModel, batch: tuple[torch.Tensor, ...], embedding: torch.Tensor) -> tuple[torch.Tensor, dict]:
    """The loss of one batch of windows (see the module docstring) and its parts."""
    start, actions, future, rewards, success, inside, before = batch
    states, predicted_rewards, logits = model.unroll(start, actions, embedding, before)
    weight = inside.float() / inside.float().sum().clamp_min(1)  # (B, L)
    state_error = (((states - future) / model.state_std) ** 2).mean(-1)
    steps = future.shape[1]
    true_rewards, true_logits = model.read_reward(future, start[:, None].expand(-1, steps, -1),
                                                  model.embed_text(embedding)[:, None].expand(-1, steps, -1))
    reward_error = (predicted_rewards - rewards) ** 2 + (true_rewards - rewards) ** 2
    success_error = (F.binary_cross_entropy_with_logits(logits, success, reduction="none")
                     + F.binary_cross_entropy_with_logits(true_logits, success, reduction="none"))
    parts = {name: (error * weight).sum() for name, error in
             (("state", state_error), ("reward", reward_error), ("success", success_error))}
    loss = parts["state"] + 10 * parts["reward"] + 0.1 * parts["success"]
    return loss, {f"train/{name}": float(value.detach()) for name, value in parts.items()}


def fit_linear_path(model: StateModel, episodes: EpisodeTensors, ridge: float) -> None:
    """Sets the dynamics' linear path to the ridge-regularised least-squares fit of every recorded
    step (`ridge` times the number of steps on the diagonal, inputs being of unit spread).

    Why: the inputs are in units of the states' spread and the output in units of one step's, so
    carrying a position forward takes gains of tens (the spread over the step), which Adam's steps
    of about the learning rate do not reach in a few thousand updates; measured, the network alone
    stayed behind a linear model of the hand. The penalty keeps the fitted system stable when it is
    iterated over many steps (an unpenalised fit of every dimension diverged).
    """
    inputs, targets = [], []
    for i, n in enumerate(episodes.lengths.tolist()):
        states, actions = episodes.states[i, : n + 1], episodes.actions[i, :n]
        before = torch.cat([torch.zeros_like(actions[:1]), actions[:-1]])
        inputs.append(model.linear_inputs(states[:-1], states[:1].expand(n, -1), actions, before))
        targets.append((states[1:] - states[:-1] - model.delta_mean) / model.delta_std)
    x = torch.cat(inputs).double()
    x = torch.cat([x, torch.ones(len(x), 1, dtype=torch.double)], dim=1)  # the bias
    gram = x.T @ x + ridge * len(x) * torch.eye(x.shape[1], dtype=torch.double)
    solution = torch.linalg.solve(gram, x.T @ torch.cat(targets).double()).float()  # (F + 1, S)
    with torch.no_grad():
        model.linear_dynamics.weight.copy_(solution[:-1].T)
        model.linear_dynamics.bias.copy_(solution[-1])


def _settings(config: StateTrainConfig) -> dict:
    """The config as JSON (paths as strings)."""
    return dataclasses.asdict(config) | {"extra_data": [str(path) for path in config.extra_data],
                                         "init": None if config.init is None else str(config.init)}


def train_state_model(data: Path, out: Path, config: StateTrainConfig, resume: bool = False,
                      progress: bool = True) -> Path:
    """Trains (or resumes) a state-model run in `out` on `data`'s episodes recorded in the real
    world (or on another robot); returns the final checkpoint directory and writes ``eval.json``."""
    dataset = EpisodeDataset(data, keys=config.keys)
    train_sources, heldout_sources = [], []
    for source in (dataset, *(EpisodeDataset(path, keys=config.keys) for path in config.extra_data)):
        usable = [i for i, info in enumerate(source.episodes) if info.in_real_world]
        train, heldout = split_episodes([source.episodes[i] for i in usable], config.heldout_fraction)
        train_sources.append((source, [usable[i] for i in train]))
        heldout_sources.append((source, [usable[i] for i in heldout]))
    train, heldout = train_sources[0][1], heldout_sources[0][1]  # the main dataset's, reported in config.json
    encoder = InstructionEncoder()
    episodes = episode_tensors(train_sources, None, encoder, progress)
    torch.manual_seed(config.seed)
    if config.init is not None and not resume:  # on resume the weights come from the run's own checkpoint
        config = dataclasses.replace(config, init=resolve_checkpoint(config.init))
    model = _initial_model(config, dataset, episodes)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(min(200, config.steps // 10), config.steps))
    sampler = torch.Generator().manual_seed(config.seed)
    resolved = {"train": _settings(config), "model": model.spec(), "data": str(data),
                "train_episodes": len(episodes.lengths),
                "heldout_episodes": sum(len(chosen) for _, chosen in heldout_sources)}
    start, metrics = begin_training(out, resolved, model, optimizer, schedule, sampler, resume,
                                    tracker=config.tracker, kind="train-state")
    checkpoint = None
    for step in tqdm(range(start, config.steps), initial=start, total=config.steps, desc="train-state", disable=not progress):
        model.train()
        index = torch.randint(len(episodes.lengths), (config.batch_size,), generator=sampler)
        times = (torch.rand(config.batch_size, generator=sampler) * episodes.lengths[index]).long()
        batch = episodes.windows(index, times, config.unroll)
        loss, values = state_loss(model, batch, episodes.embedding[index])
        gradient_step(loss, model, optimizer, schedule)
        if step % 50 == 0:
            metrics.log(step, values)
        if (step + 1) % config.checkpoint_every == 0 or step + 1 == config.steps:
            checkpoint = save_training(out, step + 1, model, resolved, optimizer, schedule, sampler)
    metrics.close()
    model.eval()
    if heldout:  # the main dataset's held-out scenes, comparable between runs with other extra data
        # Hand and object positions are read where Meta-World keeps them; another robot's states
        # have their own layout, measured as a whole.
        meta_world = not any(dataset.episodes[i].env_variant == EXTERNAL for i in heldout)
        report = evaluate_state_model(model, episode_tensors(dataset, heldout, encoder),
                                      baseline=LinearHandBaseline(episodes) if meta_world else None,
                                      positions=meta_world)
        write_json(out / "eval.json", report)
        error = "hand_cm" if meta_world else "state_rmse"
        logger.info("state model on %d held-out episodes: %s %s", len(heldout), error,
                    {h: round(v[error], 3) for h, v in report["horizons"].items()})
    return checkpoint or out


def _initial_model(config: StateTrainConfig, dataset: EpisodeDataset, episodes: EpisodeTensors) -> StateModel:
    """A fresh model, normalised by the training episodes and with its linear path fitted to them;
    or `config.init`'s, which keeps its own normalisation (its weights expect it).

    Raises:
        ValueError: `config.init`'s states or actions are not this data's.
    """
    state_dim, action_dim = episodes.states.shape[-1], episodes.actions.shape[-1]
    if config.init is not None:
        model = load_state_model(config.init)
        if (model.config.state_dim, model.config.action_dim) != (state_dim, action_dim):
            raise ValueError(f"--init {config.init}: its model takes {model.config.state_dim}-d states and "
                             f"{model.config.action_dim}-d actions; this data has {state_dim} and {action_dim}")
        return model.train()
    stats = dataset.action_stats
    spans = all(high > low for low, high in zip(stats.min, stats.max))  # else actions are taken as they are
    model = StateModel(StateModelConfig(state_dim=state_dim, action_dim=action_dim, hidden=config.hidden,
                                        last_action=config.last_action, action_low=tuple(stats.min) if spans else (),
                                        action_high=tuple(stats.max) if spans else ()))
    real = torch.cat([episodes.states[i, : n + 1] for i, n in enumerate(episodes.lengths.tolist())])
    deltas = torch.cat([episodes.states[i, 1: n + 1] - episodes.states[i, :n] for i, n in enumerate(episodes.lengths.tolist())])
    model.set_statistics(real, deltas)
    if config.ridge > 0:
        fit_linear_path(model, episodes, config.ridge)
    return model


class LinearHandBaseline:
    """How predictable the hand is from the actions alone: a least-squares linear model of the
    hand's step from this action, the last action and the last step, integrated open loop with the
    positions clipped to the recorded workspace. A state model has to beat it to be called grounded."""

    def __init__(self, episodes: EpisodeTensors) -> None:
        features, targets = [], []
        for i, n in enumerate(episodes.lengths.tolist()):
            hand, actions = episodes.states[i, : n + 1, HAND], episodes.actions[i, :n]
            steps = hand[1:] - hand[:-1]  # (n, 3)
            features.append(self._features(actions[1:], actions[:-1], steps[:-1]))
            targets.append(steps[1:])
        self.weights = torch.linalg.lstsq(torch.cat(features).double(), torch.cat(targets).double()).solution.float()
        hands = torch.cat([episodes.states[i, : n + 1, HAND] for i, n in enumerate(episodes.lengths.tolist())])
        self.low, self.high = hands.min(0).values, hands.max(0).values

    @staticmethod
    def _features(action: torch.Tensor, last_action: torch.Tensor, last_step: torch.Tensor) -> torch.Tensor:
        return torch.cat([action, last_action, last_step, torch.ones(len(action), 1)], dim=1)

    def hands(self, hand: torch.Tensor, last_step: torch.Tensor, last_action: torch.Tensor,
              actions: torch.Tensor) -> torch.Tensor:
        """(B, L, 3) hand positions after (B, L, A) `actions` from (B, 3) `hand`, whose last step and
        action were `last_step` (B, 3) and `last_action` (B, A)."""
        positions = []
        for t in range(actions.shape[1]):
            last_step = self._features(actions[:, t], last_action, last_step) @ self.weights
            hand = torch.minimum(torch.maximum(hand + last_step, self.low), self.high)
            last_action = actions[:, t]
            positions.append(hand)
        return torch.stack(positions, dim=1)


def evaluate_state_model(model: StateModel, episodes: EpisodeTensors, horizons: tuple[int, ...] = (8, 16, 40),
                         baseline: LinearHandBaseline | None = None, positions: bool = True) -> dict:
    """Open-loop errors of windows of the held-out episodes, from every 10th step of each.

    Args:
        positions: the states are Meta-World's, whose hand and first object positions are read
            out in centimetres; False (another robot's states): only the error over the whole state.

    Returns:
        ``horizons``: per h, the root-mean-square error of the imagined state after h actions
        (``state_rmse``, the dataset's units), with `positions` the mean distance (cm) between
        imagined and recorded hand and object (and the `baseline`'s hand, when given), and the
        correlation of the summed imagined and recorded rewards over the h actions;
        ``success_agreement``: how often "success within the window" agrees; ``windows``.
    """
    report = {"horizons": {}, "windows": 0}
    for h in horizons:
        index, starts = zip(*[(i, t) for i, n in enumerate(episodes.lengths.tolist()) for t in range(0, max(n - h, 1), 10)])
        index, starts = torch.tensor(index), torch.tensor(starts)
        start, actions, future, rewards, success, inside, before = episodes.windows(index, starts, h)
        imagined = model.imagine(start, actions, episodes.embedding[index], before)
        last = inside.long().sum(1).clamp_min(1) - 1  # the last step inside the episode
        rows = torch.arange(len(index))
        ended, recorded = imagined.states[rows, last], future[rows, last]  # (N, S)
        mask = inside.float()
        said = ((imagined.success > 0.5) & inside).any(1)
        real = ((success > 0.5) & inside).any(1)
        report["horizons"][str(h)] = {
            "state_rmse": float((ended - recorded).square().mean().sqrt()),
            "return_correlation": pearson((imagined.rewards * mask).sum(1), (rewards * mask).sum(1)),
            "success_agreement": float((said == real).float().mean()),
        }
        if positions:
            report["horizons"][str(h)] |= {
                "hand_cm": float(((ended[:, HAND] - recorded[:, HAND]).norm(dim=-1) * 100).mean()),
                "object_cm": float(((ended[:, OBJECT] - recorded[:, OBJECT]).norm(dim=-1) * 100).mean())}
        if baseline is not None:
            last_step = start[:, HAND] - episodes.states[index, (starts - 1).clamp(min=0), HAND]
            linear = baseline.hands(start[:, HAND], last_step, before, actions)[rows, last]
            report["horizons"][str(h)]["linear_baseline_hand_cm"] = float(
                ((linear - future[rows, last, HAND]).norm(dim=-1) * 100).mean())
        report["windows"] = len(index)
    return report
