"""How far imagination under a policy can be trusted: the judged imagined verdict against what
the same actions do in the real world, and the imagined frames against the real ones.

Legend: R rollouts in a batch, T actions per rollout (the horizon), H/W image size.

For every evaluation scene (the real first frame of an evaluation seed) the policy is rolled out
three ways, greedy:

1. in the world model, closed loop (it sees the imagined frames), the video judged by a binary
   reward (a judge): the *imagined verdict*;
2. the same actions replayed in the real world from the same scene, in an env that does not stop at
   success so that every imagined frame has a real counterpart: the *replay outcome* (success at
   any step) and the frames the imagined ones are compared with (PSNR, and PSNR on the pixels
   that moved since the start frame, as `gymnast eval-wm` measures);
3. the policy closed loop in the real world (ending at success, as `gymnast eval` does), the
   video judged by the same reward: the *real outcome*, and the judge's error on real video.

Imagined verdict vs replay outcome mixes the world model's error with the judge's; the judge on
the closed-loop real videos isolates the judge's, so the difference is the world model's.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.envs.kinds import IMAGINED, REAL
from gymnast.envs.starts import Start
from gymnast.envs.workers import parse_runner
from gymnast.eval.stats import wilson_interval
from gymnast.policy.base import Policy
from gymnast.reward.base import Reward
from gymnast.reward.spec import RewardSpec
from gymnast.world_model.base import WorldModel
from gymnast.world_model.views import replay_cameras

logger = logging.getLogger(__name__)

HORIZONS = (1, 8, 32, 64)
"""Steps at which the imagined frames' PSNR is reported (psnr_h1 ... psnr_h64)."""
VIDEO_KINDS = ("false_success", "miss", "agree", "unjudged")
"""What a side-by-side video shows, in the order videos are chosen (disagreements first)."""


@dataclass(frozen=True)
class ImaginationConfig:
    """Which scenes, how long, and how the work is batched."""

    tasks: str = "mt10"
    """Task names and/or task sets (mt10, mt50), comma-separated."""
    episodes: int = 10
    """Evaluation scenes per task (evaluation seeds 0 .. episodes - 1)."""
    horizon: int = 150
    """Actions per rollout in every env (the imagined one always runs to it)."""
    batch: int = 32
    """Rollouts stepped together in each env."""
    workers: int = 1
    """Simulator processes for the real-world envs."""
    runner: str = "local"
    """Where the simulator processes run: local, ray or ray:ADDRESS (see `gymnast eval --help`)."""
    videos: int = 4
    """Side-by-side videos (imagined | real replay | difference) to write, disagreements first."""
    seed: int = 0
    """Reset seed of the envs (what a stochastic world model draws from)."""

    def __post_init__(self) -> None:
        for name in ("episodes", "horizon", "batch", "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"ImaginationConfig.{name} must be at least 1, got {getattr(self, name)}")
        if self.videos < 0:
            raise ValueError(f"ImaginationConfig.videos must be >= 0, got {self.videos}")
        parse_runner(self.runner)


def measure_imagination(policy: Policy, world_model: WorldModel, reward: Reward, config: ImaginationConfig,
                        out: Path | None = None, progress: bool = True, labels: dict[str, str] | None = None,
                        robot_state=None) -> dict:
    """Measures imagination under `policy` (see the module docstring); writes the report into `out`.

    Args:
        policy: any `Policy` (a wrapped one too, e.g. with action noise); rolled out greedy.
        world_model: imagines the rollouts; its image size is the envs'.
        reward: a binary reward (``reward.binary``) that judges imagined and real videos.
        config: scenes, horizon, batching and videos.
        out: directory for imagination.json, imagination.md, psnr.png and videos/ (None: nothing written).
        progress: show a progress bar over the batches.
        labels: what the objects are (e.g. run paths), recorded in the settings.
        robot_state: for a policy that reads the robot's state, what imagines it beside the world
            model (`gymnast.world_model.robot_state.robot_state_in_imagination`).

    Returns:
        imagination.json's content: ``settings``; ``overall`` and ``per_task`` blocks (see
        `summarize_rows`); ``psnr`` (``psnr_h1`` ... ``psnr_full``, ``moving_psnr_h1`` ...,
        per-step ``curve`` and ``moving_curve``); ``interactions`` (``replay``, ``real``,
        ``total``); ``seconds``; ``rollouts`` (one record per scene); ``videos``; ``files``.

    Raises:
        ValueError: `reward` is not binary (a continuous score is no success verdict).
    """
    from gymnast.envs.factory import EnvFactory
    from gymnast.envs.starts import evaluation_starts
    from gymnast.envs.tasks import resolve_tasks

    if not reward.binary:
        raise ValueError(f"imagination needs a binary reward (a judge that says success or not); {type(reward).__name__} "
                         "gives continuous scores, which are no success verdict to compare with the real world")
    began = time.perf_counter()
    tasks = resolve_tasks(config.tasks)
    env_config = EnvConfig(image_size=world_model.image_size, horizon=config.horizon, cameras=replay_cameras(world_model))
    starts = evaluation_starts(tasks, config.episodes, env_config)
    size = min(config.batch, len(starts))
    envs = EnvFactory(IMAGINED, policy.chunk_size, env_config, "none", config.workers, world_model,
                      robot_state=robot_state)
    # Replays run in an env that goes on after success, so each imagined frame has a real one.
    replays = EnvFactory(REAL, policy.chunk_size, dataclasses.replace(env_config, terminate_on_success=False), "none",
                         config.workers, runner=config.runner)
    state = _State(config.videos)
    try:
        for first in tqdm(range(0, len(starts), size), desc="imagination", unit="batch", disable=not progress):
            _measure_batch(starts[first: first + size], size, policy, reward, envs, replays, config.seed, state)
    finally:
        envs.close()
        replays.close()
    state.seconds["total"] = time.perf_counter() - began
    report = _report(state, tasks, config, labels or {}, policy, world_model, reward)
    if out is not None:
        from gymnast.experiment.imagination_report import write_imagination_report

        report = write_imagination_report(report, _chosen_videos(state, config.videos), out)
    overall = report["overall"]
    logger.info("imagination: agreement %s, imagined success %.2f, replay %.2f, real %.2f over %d scenes",
                overall["agreement"], overall["imagined_success"]["success"], overall["replay_success"]["success"],
                overall["real_success"]["success"], overall["episodes"])
    return report


def measure_imagination_runs(policy: str | Path, wm: str | Path, reward: RewardSpec, config: ImaginationConfig,
                             out: Path | None = None, progress: bool = True, robot_state: str | Path | None = None
                             ) -> dict:
    """`measure_imagination` of saved runs: a policy run, a world-model run and a reward spec
    (``judge:RUN`` or ``vlm:MODEL@BASE_URL``, see `gymnast.reward.spec`), and for a policy that
    reads the robot's state, the state model run that imagines it (``--robot-state``)."""
    from gymnast.reward.select import make_reward
    from gymnast.world_model.base import load_world_model

    world_model = load_world_model(wm)
    judge = make_reward(reward, world_model)
    loaded, state, labels = measured_policy(policy, world_model, wm, reward, judge, robot_state)
    return measure_imagination(loaded, world_model, judge, config, out, progress, labels, state)


def measured_policy(policy: str | Path, world_model: WorldModel, wm: str | Path, reward: RewardSpec, judge: Reward,
                    robot_state: str | Path | None):
    """A saved policy as the measurements of imagination take it (`measure_imagination_runs`,
    `gymnast.experiment.practice_signal.measure_signal_runs`): loaded and checked to see the world
    model's cameras, which `judge` (the reward `reward` made) must see too; what imagines its robot
    state, if it reads one (``--robot-state``,
    `gymnast.world_model.robot_state.robot_state_in_imagination`); and the labels the report records."""
    from gymnast.policy.load import load_policy
    from gymnast.reward.judges.base import check_judge_sees
    from gymnast.world_model.base import grounded_state_dim
    from gymnast.world_model.robot_state import robot_state_in_imagination
    from gymnast.world_model.views import check_policy_views

    loaded = load_policy(policy)
    cameras = getattr(loaded.config, "cameras", ())
    check_policy_views(cameras, world_model, policy, wm)
    check_judge_sees(judge, cameras, loaded.config.image_size, reward.run, f"the policy {policy}")
    state = robot_state_in_imagination(getattr(loaded, "state_dim", 0), robot_state, policy, wm,
                                       grounded_state_dim(world_model))
    labels = {"policy": str(policy), "wm": str(wm), "reward": str(reward)}
    if robot_state is not None:
        labels["robot_state"] = str(robot_state)
    return loaded, state, labels


@dataclass
class _State:
    """What the batches add up: one record per scene, per-step PSNR, costs, video candidates."""

    videos: int
    rows: list[dict] = dataclasses.field(default_factory=list)
    psnr: list[torch.Tensor] = dataclasses.field(default_factory=list)  # (T,) per scene
    moving_psnr: list[torch.Tensor] = dataclasses.field(default_factory=list)  # (T,) per scene
    interactions: dict[str, int] = dataclasses.field(default_factory=lambda: {"replay": 0, "real": 0})
    seconds: dict[str, float] = dataclasses.field(default_factory=lambda: dict.fromkeys(
        ("imagine", "judge", "replay", "real"), 0.0))
    # kind -> [(row index, imagined (T + 1, H, W, 3), replayed (T + 1, H, W, 3))], at most `videos`
    # each: keeping every video would hold hundreds of MB on MT10.
    candidates: dict[str, list] = dataclasses.field(default_factory=lambda: {kind: [] for kind in VIDEO_KINDS})


def _measure_batch(batch: Sequence[Start], size: int, policy: Policy, reward: Reward, envs, replays, seed: int,
                   state: _State) -> None:
    """Imagines, judges, replays and runs for real the scenes of one batch; adds to `state`."""
    from gymnast.rl.evaluate import replay_actions, verdicts
    from gymnast.rl.rollout import collect_rollouts, score_groups
    from gymnast.world_model.metrics import masked_psnr, moving_mask, psnr, to_unit_float

    count = len(batch)
    batch = list(batch) + [batch[0]] * (size - count)  # the envs have a fixed size; extra rollouts are dropped

    def timed(name: str, work):
        began = time.perf_counter()
        result = work()
        state.seconds[name] += time.perf_counter() - began
        return result

    imagined = timed("imagine", lambda: collect_rollouts(envs.get(IMAGINED, size), policy, batch, 0.0,
                                                         torch.Generator(), seed))
    imagined_scores = timed("judge", lambda: score_groups(reward, imagined, 1))  # (R,)
    verdict = verdicts(imagined, imagined_scores, reward)  # (R,) 0/1, NaN where unjudged
    replay = timed("replay", lambda: replay_actions(replays.get(REAL, size), imagined.starts, imagined.actions,
                                                    imagined.lengths))
    replay_success, replayed, replay_steps = replay.success, replay.frames, replay.interactions
    real = timed("real", lambda: collect_rollouts(envs.get(REAL, size), policy, batch, 0.0, torch.Generator(), seed))
    real_scores = timed("judge", lambda: score_groups(reward, real, 1))  # (R,)
    # The padding rollouts' interactions are not counted (`gymnast eval` would not run them). Every
    # imagined rollout runs to the horizon, so every replay executes as many actions.
    state.interactions["replay"] += replay_steps // size * count
    state.interactions["real"] += int(real.lengths[:count].sum())

    for i, start in enumerate(batch[:count]):
        # One rollout at a time: a whole batch in float would take GBs at MT10's horizon.
        fake, true = to_unit_float(imagined.frames[i, 1:]), to_unit_float(replayed[i, 1:])  # (T, 3, H, W)
        mask = moving_mask(true, to_unit_float(replayed[i, :1]))  # (T, 1, H, W) moved since the start frame
        state.psnr.append(psnr(fake, true))  # (T,)
        state.moving_psnr.append(masked_psnr(fake, true, mask))  # (T,) NaN where nothing moved
        judged = bool(torch.isfinite(verdict[i]))
        imagined_verdict = bool(verdict[i] > 0.5) if judged else None
        real_verdict = bool(real_scores[i] > 0.5) if torch.isfinite(real_scores[i]) else None
        row = {"task": start.task, "seed": start.seed, "imagined_score": _finite(imagined_scores[i]),
               "imagined_verdict": imagined_verdict, "replay_success": bool(replay_success[i]),
               "real_success": bool(real.success[i]), "real_length": int(real.lengths[i]),
               "real_score": _finite(real_scores[i]), "real_verdict": real_verdict,
               "psnr_full": _finite(state.psnr[-1].mean()), "moving_psnr_full": _finite(state.moving_psnr[-1].nanmean())}
        kind = _kind(imagined_verdict, row["replay_success"])
        if len(state.candidates[kind]) < state.videos:
            # Copies: a view would keep the whole batch's frames alive.
            state.candidates[kind].append((len(state.rows), imagined.frames[i].numpy().copy(), replayed[i].numpy().copy()))
        state.rows.append(row | {"kind": kind})


def _kind(verdict: bool | None, replay: bool) -> str:
    if verdict is None:
        return "unjudged"
    if verdict == replay:
        return "agree"
    return "false_success" if verdict else "miss"


def _finite(value: torch.Tensor) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def _chosen_videos(state: _State, count: int) -> list[tuple[dict, np.ndarray, np.ndarray]]:
    """Up to `count` (row, imagined, replayed): false successes and misses in turn, then the rest."""
    pools = state.candidates
    disagreements = [pool[i] for i in range(count) for pool in (pools["false_success"], pools["miss"]) if i < len(pool)]
    chosen = (disagreements + pools["agree"] + pools["unjudged"])[:count]
    return [(state.rows[index], fake, true) for index, fake, true in chosen]


def _rate(hits: list[bool]) -> dict:
    """Success rate with its 95% Wilson interval (None where there are no episodes)."""
    if not hits:
        return {"success": None, "ci_low": None, "ci_high": None, "successes": 0, "episodes": 0}
    low, high = wilson_interval(sum(hits), len(hits))
    return {"success": sum(hits) / len(hits), "ci_low": low, "ci_high": high, "successes": sum(hits), "episodes": len(hits)}


def _share(top: int, bottom: int) -> float | None:
    return top / bottom if bottom else None


def _confusion(said: list[bool], truth: list[bool]) -> dict:
    """Counts of a verdict against the truth, and the shares read from them (None where undefined)."""
    tp = sum(s and t for s, t in zip(said, truth))
    fp = sum(s and not t for s, t in zip(said, truth))
    fn = sum(t and not s for s, t in zip(said, truth))
    tn = len(said) - tp - fp - fn
    return {"confusion": {"tp": tp, "fp": fp, "fn": fn, "tn": tn}, "agreement": _share(tp + tn, len(said)),
            "tpr": _share(tp, tp + fn), "fpr": _share(fp, fp + tn)}


def summarize_rows(rows: list[dict]) -> dict:
    """One block of figures over scene records (all, or one task's).

    Returns:
        ``episodes``; ``judged`` (scenes whose imagined video got a verdict); ``confusion``
        (``tp``, ``fp``, ``fn``, ``tn``: imagined verdict against the replay outcome, over the
        judged scenes), ``agreement``, ``false_success`` (share of imagined successes that failed
        on replay), ``missed_success`` (share of replay successes judged failures);
        ``imagined_success``, ``replay_success``, ``real_success`` (closed loop), each
        ``{success, ci_low, ci_high, successes, episodes}``; ``judge_on_real`` (the judge on the
        closed-loop real videos against their real outcome: ``confusion``, ``agreement``, ``tpr``,
        ``fpr``, ``judged``); ``psnr_full`` and ``moving_psnr_full`` (means over the scenes).
        Shares with nothing to divide by are None.
    """
    judged = [row for row in rows if row["imagined_verdict"] is not None]
    imagined = _confusion([row["imagined_verdict"] for row in judged], [row["replay_success"] for row in judged])
    counts = imagined["confusion"]
    real_judged = [row for row in rows if row["real_verdict"] is not None]
    on_real = _confusion([row["real_verdict"] for row in real_judged], [row["real_success"] for row in real_judged])
    psnrs = [row["psnr_full"] for row in rows if row["psnr_full"] is not None]
    moving = [row["moving_psnr_full"] for row in rows if row["moving_psnr_full"] is not None]
    return {
        "episodes": len(rows), "judged": len(judged), "confusion": counts, "agreement": imagined["agreement"],
        "false_success": _share(counts["fp"], counts["tp"] + counts["fp"]),
        "missed_success": _share(counts["fn"], counts["tp"] + counts["fn"]),
        "imagined_success": _rate([row["imagined_verdict"] for row in judged]),
        "replay_success": _rate([row["replay_success"] for row in rows]),
        "real_success": _rate([row["real_success"] for row in rows]),
        "judge_on_real": {**on_real, "judged": len(real_judged)},
        "psnr_full": float(np.mean(psnrs)) if psnrs else None,
        "moving_psnr_full": float(np.mean(moving)) if moving else None,
    }


def _psnr_figures(state: _State) -> dict:
    """PSNR of the imagined frames against the replayed ones, by horizon and per step."""
    from gymnast.world_model.metrics import summarize_horizons

    figures = {}
    for name, parts in (("psnr", state.psnr), ("moving_psnr", state.moving_psnr)):
        values = torch.stack(parts)  # (scenes, T)
        summary = summarize_horizons(values, HORIZONS)
        figures |= {f"{name}_h{h}": summary[f"h{h}"] for h in HORIZONS} | {f"{name}_full": summary["full"]}
        curve = torch.nanmean(values.double(), dim=0).tolist()  # (T,): NaN where no pixel moved in any scene
        figures["curve" if name == "psnr" else "moving_curve"] = [v if np.isfinite(v) else None for v in curve]
    return figures


def _report(state: _State, tasks: Sequence[str], config: ImaginationConfig, labels: dict[str, str], policy: Policy,
            world_model: WorldModel, reward: Reward) -> dict:
    settings = {**dataclasses.asdict(config), **labels, "task_list": list(tasks), "image_size": world_model.image_size,
                "chunk_size": policy.chunk_size, "reward_type": type(reward).__name__, "policy_type": type(policy).__name__}
    interactions = {**state.interactions, "total": sum(state.interactions.values())}
    return {
        "settings": settings,
        "overall": summarize_rows(state.rows),
        "per_task": {task: summarize_rows([row for row in state.rows if row["task"] == task]) for task in tasks},
        "psnr": _psnr_figures(state),
        "interactions": interactions,
        "seconds": state.seconds,
        "rollouts": state.rows,
        "videos": [],
        "files": {},
    }


def imagination_brief(report: dict) -> dict:
    """The main figures of a report (what the experiment's summary.json keeps): overall agreement,
    confusion counts, false and missed successes, the three success rates with their intervals,
    the judge on real videos, PSNR at a few horizons and the real interactions."""
    overall, figures = report["overall"], report["psnr"]
    judge = overall["judge_on_real"]
    return {
        "episodes": overall["episodes"], "agreement": overall["agreement"], "confusion": overall["confusion"],
        "false_success": overall["false_success"], "missed_success": overall["missed_success"],
        **{name: overall[name] for name in ("imagined_success", "replay_success", "real_success")},
        "judge_on_real": {key: judge[key] for key in ("agreement", "tpr", "fpr", "confusion")},
        **{key: figures[key] for key in ("psnr_h1", "psnr_h8", "psnr_h32", "psnr_full", "moving_psnr_h32", "moving_psnr_full")},
        "real_interactions": report["interactions"]["total"],
        "per_task_agreement": {task: block["agreement"] for task, block in report["per_task"].items()},
    }
