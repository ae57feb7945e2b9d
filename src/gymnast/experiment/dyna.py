"""`gymnast dyna`: World-Gymnast's iterative loop of practice in imagination and a little reality.

Each round k (1..rounds), from the policy, world model and reward model that round k-1 left:

1. RL in imagination: `rl.steps` GRPO steps in the world model (`gymnast.rl.train.train_rl`),
   rewarded by the judge or by the grounded state model's reward head (``state``, `gymnast
   train-state`, one run or an ensemble), from the original dataset's scenes, or, with
   `practice_from_rollouts`, from the previous round's recorded rollouts: the policy's own newest
   real states, where WoVR restarts imagination.
2. Real rollouts: `rollouts_per_task` episodes per task of the new policy in the real world
   (`gymnast.eval.record.record_policy`), from data seeds only; with `record` ``plans``, the
   policy's imagined plans instead: each episode planned closed loop in the round's world model
   and executed in the real world, so that the refit sees what the actions the policy chose on the
   model's own frames really do (where r4 of `gymnast ladder` found the model wrong, while it is
   right about the actions the policy takes in the real world). These are the only real
   interactions Dyna spends on training, and they are counted from the recorded dataset. The
   last round takes none (and skips step 3): nothing after it would learn from them.
3. Fine-tuning: the world model and the reward model each continue from their last weights on their
   own original data plus every round's recorded rollouts (``init`` and ``extra_data`` of
   `train_world_model`, `train_judge` and `train_state_model`; every member of an ensemble). A world
   model of one's own (``python:`` or ``plugin:``, `gymnast.utils.plugins`) says nothing of how it
   is trained, so every round imagines in it as given (`can_be_refit`). The
   rollouts carry Meta-World's per-step success flags and rewards, so the judge's false positives
   (failures it passed) become labelled negatives, and the state model learns the states the
   practised policy reaches, where its reward head was wrong in the direction practice exploited
   (the lever that lifted its ranking most, docs/world_model.md).
4. Evaluation: `gymnast eval` in the real world on the evaluation seeds; these episodes measure
   and are counted apart from the training interactions.

Round 0 is the starting policy's evaluation. Every part of a round is a stage
(`gymnast.experiment.stages.Stages`, records in OUT/round_k/stages/), so a rerun skips what
finished, and the trainers under a part cut short continue from their last checkpoint.

The comparison arm (``real_rl``) is RL in the real world with the same `RLConfig` for as many
steps as all rounds together, evaluated at every round's boundary the same way.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from gymnast.config import EnvConfig
from gymnast.envs.parallel import kept_workers
from gymnast.envs.workers import parse_runner
from gymnast.experiment.stages import Stages
from gymnast.rl.config import RL_PRESETS, RLConfig
from gymnast.utils.atomic import read_json
from gymnast.utils.checkpoint import has_checkpoint
from gymnast.utils.plugins import is_plugin
from gymnast.utils.settings import from_json, saved_settings

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class DynaConfig:
    """Settings of the Dyna loop; `rl` holds the GRPO settings shared with the real-world arm."""

    rounds: int = 4
    """Rounds of imagined RL, real rollouts and fine-tuning."""
    real_rl: bool = True
    """Also run the comparison arm: RL in the real world, same settings, rounds x rl.steps steps."""
    real_reward: str = "sim"
    """Reward of the real-world arm (sim: Meta-World's success; sim-dense: its shaped reward)."""
    rollouts_per_task: int = 8
    """Real episodes of the current policy recorded per task and round (the training interactions)."""
    record: str = "rollouts"
    """What each round records for the refit: ``rollouts``, the policy acting in the real world; or
    ``plans``, the policy's plans made closed loop in the round's world model and executed in the
    real world (`gymnast collect --imagine-with`): the actions chosen on the model's own frames,
    which it imagines succeeding where they fail."""
    rollout_temperature: float = 1.0
    """Temperature of the recorded rollouts' action tokens: sampled, as in RL, so they hold the
    failures the judge should learn to refuse as well as successes."""
    first_rollout_seed: int = 100_000
    """Data seed of every task's first recorded rollout in round 1; each round records new scenes
    after the last round's. Fresh scenes, not the dataset's: the SFT policy already solves most of
    its own demonstrations' scenes (docs/rl.md), so rollouts there hold few of the failures the
    judge must learn to refuse."""
    wm_steps: int = 300
    """Fine-tuning steps of the world model per round (0: every round imagines in the given one)."""
    judge_steps: int = 200
    """Fine-tuning steps of the judge per round (0: every round judges with the given one)."""
    state_steps: int = 500
    """Fine-tuning steps of the state model (of each member of an ensemble) per round (0: every round
    rewards with the given one)."""
    practice_from_rollouts: bool = False
    """Rounds after the first practise from the previous round's recorded rollouts (their first
    frames, or frames within them with `rl.keyframes`) instead of the original dataset's scenes."""
    eval_episodes: int = 20
    """Real evaluation episodes per task after each round, from the evaluation seeds."""
    workers: int = 2
    """Simulator processes (recording, evaluation, real-world RL)."""
    runner: str = "local"
    """Where the simulator processes run: local, ray or ray:ADDRESS (see `gymnast eval --help`)."""
    rl: RLConfig = field(default_factory=RLConfig)
    """GRPO settings of every round's imagined RL and of the real-world arm."""

    def __post_init__(self) -> None:
        for name in ("rounds", "rollouts_per_task", "eval_episodes", "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"DynaConfig.{name} must be at least 1, got {getattr(self, name)}")
        for name in ("wm_steps", "judge_steps", "state_steps"):
            if getattr(self, name) < 0:
                raise ValueError(f"DynaConfig.{name} must be at least 0, got {getattr(self, name)}")
        if self.rollout_temperature < 0:
            raise ValueError(f"DynaConfig.rollout_temperature must be >= 0, got {self.rollout_temperature}")
        if self.record not in ("rollouts", "plans"):
            raise ValueError(f"DynaConfig.record must be rollouts or plans, got {self.record!r}")
        if self.real_reward not in ("sim", "sim-dense"):
            raise ValueError(f"DynaConfig.real_reward must be sim or sim-dense, got {self.real_reward!r}")
        parse_runner(self.runner)

    def reward_steps(self, kind: str) -> int:
        """Fine-tuning steps a round gives the reward model of `kind` (``judge`` or ``state``)."""
        return self.judge_steps if kind == "judge" else self.state_steps

    @property
    def imagined_rl_config(self) -> RLConfig:
        """Each round's imagined RL: Dyna's settings, its imagined evaluation on the seeds (and as
        many of them) as the round's real one, so that the two read side by side."""
        return dataclasses.replace(self.rl, eval_episodes=self.eval_episodes)

    @property
    def real_rl_config(self) -> RLConfig:
        """The real-world arm's settings: Dyna's, for all rounds' steps, evaluated at each round's end."""
        return dataclasses.replace(self.rl, steps=self.rounds * self.rl.steps, eval_every=self.rl.steps,
                                   eval_episodes=self.eval_episodes, watch_every=0, workers=self.workers,
                                   runner=self.runner)


def _imagined_rl(**changes) -> RLConfig:
    # The round's `gymnast eval` measures the policy in the real world; RL's own real evaluation
    # would spend the same interactions again.
    return dataclasses.replace(RL_PRESETS["full"], real_eval=False, eval_every=0, **changes)


DYNA_PRESETS: dict[str, DynaConfig] = {
    "debug": DynaConfig(rounds=3, rollouts_per_task=1, wm_steps=2, judge_steps=2, eval_episodes=1, workers=1,
                        rl=dataclasses.replace(RL_PRESETS["debug"], real_eval=False, eval_every=0, watch_every=0,
                                               tracker=())),
    # Minutes on 2 cores: one refill-free round of 32 rollouts per step.
    "demo": DynaConfig(rounds=3, rollouts_per_task=8, wm_steps=100, judge_steps=100, eval_episodes=10,
                       rl=_imagined_rl(steps=4, tasks="reach-v3", lr=3e-5, max_rounds=1, watch_every=4)),
    "full": DynaConfig(rounds=5, rl=_imagined_rl(steps=10, tasks="reach-v3,push-v3,pick-place-v3,peg-insert-side-v3",
                                                starts_per_step=8, lr=3e-5)),
}


def with_recipe(config: DynaConfig, run: Path, steps: int | None = None) -> DynaConfig:
    """`config` practising with the GRPO settings saved in `run` (RUN/config.json's ``rl``, as an RL
    run or a ladder saves them), so that the loop can be held against a ladder's rungs on the same
    recipe. What belongs to the loop stays its own: `steps` a round (default: `config`'s), no real
    evaluation inside RL (each round's evaluation measures the policy), and the watch, the videos
    and the checkpoints at most a round apart, so that every round has them.

    Raises:
        FileNotFoundError: `run` holds no config.json.
        ValueError: its config.json holds no ``rl`` settings (naming the file).
    """
    path = Path(run) / "config.json"
    if not path.exists():
        raise FileNotFoundError(f"the recipe {run} holds no config.json: give an RL run or a ladder directory")
    saved = read_json(path).get("rl")
    if not isinstance(saved, dict):
        raise ValueError(f"{path} holds no rl settings: give an RL run or a ladder directory")
    recipe, steps = from_json(RLConfig, saved), steps or config.rl.steps

    def each_round(every: int) -> int:
        return min(every, steps) if every else 0

    return dataclasses.replace(config, rl=dataclasses.replace(
        recipe, steps=steps, real_eval=False, eval_every=0, watch_every=each_round(recipe.watch_every),
        video_every=each_round(recipe.video_every), checkpoint_every=each_round(recipe.checkpoint_every)))


@dataclass(frozen=True)
class DynaInputs:
    """What the loop starts from: runs of the policy, world model and reward model (a judge, or a
    state model: one run or an ensemble of them), and the dataset whose scenes imagined RL starts
    from (None: the one the policy was trained on)."""

    policy: Path
    wm: Path
    judge: Path | None = None
    data: Path | None = None
    state: Path | None = None

    @property
    def reward_kind(self) -> str:
        """``judge`` or ``state``: which of the two reward models the loop practises on and refits."""
        return "judge" if self.judge is not None else "state"

    @property
    def reward_model(self) -> Path:
        """The run (or ensemble directory) of that reward model."""
        return self.judge if self.judge is not None else self.state

    def check(self) -> None:
        """Raises FileNotFoundError or ValueError, naming the input, before anything runs."""
        from gymnast.world_model.ensemble import is_ensemble, member_paths

        if (self.judge is None) == (self.state is None):
            raise ValueError("dyna practises on one reward model: give --judge RUN or --state RUN, not "
                             f"{'both' if self.judge is not None else 'neither'}")
        # A policy or world model of one's own is no run directory: its factory loads it (RL reads it).
        runs = [(name, run) for name, run in (("policy", self.policy), ("wm", self.wm)) if not is_plugin(run)]
        if self.state is not None and is_ensemble(self.state):
            runs += [("state", member) for member in member_paths(self.state)]
        else:
            runs.append((self.reward_kind, self.reward_model))
        for name, run in runs:
            if not (Path(run) / "config.json").is_file():
                raise FileNotFoundError(f"--{name} {run}: no run there (no config.json); dyna fine-tunes a single "
                                        f"{'world-model' if name == 'wm' else name} run"
                                        f"{' or an ensemble of state-model runs' if name == 'state' else ''}")
        for name, run in runs:
            if name != "policy" and not saved_settings(run).get("data"):
                raise ValueError(f"--{name} {run} does not say which dataset it was trained on")
        if self.data is not None and not Path(self.data).is_dir():
            raise FileNotFoundError(f"--data {self.data}: no such directory")

    def to_json(self) -> dict:
        return {name: None if value is None else str(value) for name, value in dataclasses.asdict(self).items()}


def check_refit_data(config: DynaConfig, inputs: DynaInputs) -> None:
    """Every model the rounds refit continues on the datasets it was trained on (RUN/config.json's
    ``data`` and ``train.extra_data``) plus the rounds' rollouts: raises FileNotFoundError, naming the
    model and the dataset, before anything runs, where one is no longer there."""
    from gymnast.world_model.ensemble import is_ensemble, member_paths

    refit = []
    if config.wm_steps and can_be_refit(inputs.wm):
        refit.append(("wm", inputs.wm))
    if config.reward_steps(inputs.reward_kind):
        model = inputs.reward_model
        members = member_paths(model) if inputs.reward_kind == "state" and is_ensemble(model) else [model]
        refit += [(inputs.reward_kind, member) for member in members]
    for name, run in refit:
        saved = saved_settings(run)
        for data in (saved.get("data"), *saved.get("train", {}).get("extra_data", ())):
            if data and not (Path(data) / "meta" / "info.json").is_file():
                steps = {"wm": "--wm-steps"}.get(name, f"--{name}-steps")
                raise FileNotFoundError(
                    f"--{name} {run} was trained on {data}, which is not here (no meta/info.json): each round refits "
                    f"it on its datasets plus the round's rollouts; record {data} again, or give {steps} 0 to keep "
                    f"the {name} as it is")


def saved_dyna_settings(out: Path) -> tuple[DynaConfig, DynaInputs]:
    """The settings and inputs a Dyna run in `out` was started with, for ``--resume``."""
    saved = saved_settings(out)
    return from_json(DynaConfig, saved["dyna"]), from_json(DynaInputs, saved["inputs"])


def run_dyna(config: DynaConfig, inputs: DynaInputs, out: Path, progress: bool = True) -> dict:
    """Runs (or continues) the Dyna loop in `out`; returns the summary (also OUT/summary.json).

    Raises:
        ValueError: `out` holds a Dyna run started with other settings or inputs.
    """
    from gymnast.experiment.dyna_report import track_report, write_report
    from gymnast.utils.checkpoint import write_run_config

    inputs.check()
    check_refit_data(config, inputs)
    resolved = {"dyna": dataclasses.asdict(config), "inputs": inputs.to_json()}
    if (out / "config.json").exists() and not _same_run(saved_dyna_settings(out), config, inputs):
        raise ValueError(f"{out} holds a Dyna run with other settings or inputs; continue it with "
                         f"`gymnast dyna --out {out} --resume`, or start a new run in another --out")
    write_run_config(out, resolved)
    began = time.perf_counter()
    stages = Stages(out)
    # The rounds' evaluations and recordings share one set of simulator processes instead of
    # starting one each (seconds of imports every time); each reads a policy run already finished.
    with kept_workers(config.workers, config.runner):
        rounds = [stages.run("round_0_eval", lambda: _evaluate(inputs.policy, config, out / "round_0" / "eval.json"))]
        policy, wm, reward, recorded = inputs.policy, inputs.wm, inputs.reward_model, []
        for k in range(1, config.rounds + 1):
            policy, wm, reward, row = run_round(k, config, inputs, policy, wm, reward, recorded, out, progress)
            rounds.append(row)
            logger.info("dyna round %d: real success %.1f%% [%.1f, %.1f]; its rollouts took %d real actions", k,
                        100 * row["success"], 100 * row["ci_low"], 100 * row["ci_high"],
                        row.get("rollouts", {}).get("real_interactions", 0))
    real_rl = stages.run("real_rl", lambda: run_real_rl(config, inputs, out / "real_rl", progress),
                         out / "real_rl") if config.real_rl else None
    summary = summarise(config, rounds, real_rl)
    summary["wall_s"] = time.perf_counter() - began
    summary = write_report(summary, out)
    track_report(summary, out, config.rl.tracker, resolved)
    return summary


def _same_run(saved: tuple[DynaConfig, DynaInputs], config: DynaConfig, inputs: DynaInputs) -> bool:
    """Whether the run saved in OUT is the one `config` and `inputs` describe; where it logs (its
    trackers) may change (older runs' settings are read under today's names)."""
    settings, started_from = saved
    settings = dataclasses.replace(settings, rl=dataclasses.replace(settings.rl, tracker=config.rl.tracker))

    def as_json(*objects) -> list:
        return json.loads(json.dumps([dataclasses.asdict(item) for item in objects], default=str))  # paths as strings

    return as_json(settings, started_from) == as_json(config, inputs)


def run_round(k: int, config: DynaConfig, inputs: DynaInputs, policy: Path, wm: Path, reward: Path,
              recorded: list[Path], out: Path, progress: bool) -> tuple[Path, Path, Path, dict]:
    """One round in OUT/round_k/: the new policy, world model and reward model (judge or state
    model, `inputs.reward_kind`), and the round's figures. `recorded` (every round's rollout
    dataset so far) gains this round's."""
    from gymnast.envs.kinds import IMAGINED
    from gymnast.reward.spec import RewardSpec
    from gymnast.rl.config import RLRun
    from gymnast.rl.train import train_rl

    here = out / f"round_{k}"
    stages = Stages(here)
    kind = inputs.reward_kind
    rl_run, rollouts, new_wm, new_reward = here / "rl", here / "rollouts", here / "world_model", here / kind
    starts = recorded[-1] if config.practice_from_rollouts and recorded else inputs.data
    spec = RLRun(str(policy), IMAGINED, RewardSpec(kind, run=Path(reward)), wm=str(wm), data=_str(starts))
    trained = stages.run("rl", lambda: _rl_record(train_rl(spec, rl_run, config.imagined_rl_config,
                                                           resume=has_checkpoint(rl_run), progress=progress)), rl_run)
    row = {"round": k, "rl_steps": k * config.rl.steps, "rl": trained}
    if k < config.rounds:  # the last round's rollouts could no longer change the policy: none are taken
        judge = reward if kind == "judge" else None
        planned_in = wm if config.record == "plans" else None
        row["rollouts"] = stages.run("rollouts", lambda: record_rollouts(k, rl_run, judge, config, rollouts, progress,
                                                                         planned_in), rollouts)
        recorded.append(rollouts)
        if config.wm_steps and can_be_refit(inputs.wm):  # else every round imagines in the given world model
            stages.run("world_model", lambda: fine_tune_world_model(inputs.wm, wm, recorded, config.wm_steps, new_wm,
                                                                    progress, config.rl.tracker), new_wm)
            wm = new_wm
        if config.reward_steps(kind):  # else every round rewards with the given model
            if kind == "judge":
                row["judge"] = stages.run("judge", lambda: fine_tune_judge(inputs.judge, reward, wm, recorded,
                                                                           config.judge_steps, new_reward, progress,
                                                                           config.rl.tracker), new_reward)
            else:
                row["state"] = stages.run("state", lambda: fine_tune_state_model(inputs.state, reward, recorded,
                                                                                 config.state_steps, new_reward,
                                                                                 progress, config.rl.tracker),
                                          new_reward)
            reward = new_reward
    evaluated = stages.run("eval", lambda: _evaluate(rl_run, config, here / "eval.json"))
    return rl_run, wm, reward, {**evaluated, **row}


def record_rollouts(k: int, policy: Path, judge: Path | None, config: DynaConfig, out: Path, progress: bool,
                    planned_in: str | Path | None = None) -> dict:
    """Records round `k`'s real rollouts (with `planned_in` a world model: the policy's plans made in
    it, executed for real); returns their count, success, real interactions (actions taken, from the
    dataset itself) and how the judge that guided the round's RL, if one did, scores them."""
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.eval.record import record_real_rollouts
    from gymnast.reward.judges.measure import evaluate_judge
    from gymnast.reward.judges.train import load_judge
    from gymnast.reward.judges.videos import load_videos

    counts = record_real_rollouts(policy, config.rl.tasks, config.rollouts_per_task,
                                  config.first_rollout_seed + (k - 1) * config.rollouts_per_task,
                                  config.rollout_temperature, config.rl.evaluation_horizon, config.workers,
                                  config.runner, out, progress, imagine_with=planned_in)
    if judge is None:
        return counts
    model = load_judge(judge)
    dataset = EpisodeDataset(out, cameras=model.config.cameras)  # the views the judge sees, side by side
    # Before fine-tuning: how often the judge passed a failure (the errors this round teaches it).
    judge_report = evaluate_judge(model, load_videos(dataset, list(range(len(dataset))), None, False))
    return {**counts, "judge_before": judge_report}


def fine_tune_world_model(original: Path, current: Path, recorded: list[Path], steps: int, out: Path,
                          progress: bool, tracker: tuple[str, ...] | None = None) -> dict:
    """The world model `current`, fine-tuned for `steps` on `original`'s data plus every recorded rollout,
    logging to the trackers `tracker` (None: the original run's)."""
    from gymnast.world_model.train import saved_train_config, train_world_model

    settings = _fine_tuning(saved_train_config(original), steps, current, recorded, validate_every=steps,
                            video_every=steps, **_logging_to(tracker))
    checkpoint = train_world_model(Path(saved_settings(original)["data"]), out, settings, resume=has_checkpoint(out),
                                   progress=progress)
    return {"checkpoint": str(checkpoint)}


def fine_tune_judge(original: Path, current: Path, wm: Path, recorded: list[Path], steps: int, out: Path,
                    progress: bool, tracker: tuple[str, ...] | None = None) -> dict:
    """The judge `current`, fine-tuned for `steps` on `original`'s data plus every recorded rollout (re-imagined
    by the round's world model when the original judge learned from imagined video too), logging to `tracker`
    (None: the original run's)."""
    from gymnast.reward.judges.train import saved_judge_config, train_judge

    saved = saved_settings(original)
    settings = _fine_tuning(saved_judge_config(original), steps, current, recorded, **_logging_to(tracker))
    return train_judge(Path(saved["data"]), out, settings, wm=wm if saved.get("wm") else None, resume=has_checkpoint(out),
                       progress=progress)


def fine_tune_state_model(original: Path, current: Path, recorded: list[Path], steps: int, out: Path,
                          progress: bool, tracker: tuple[str, ...] | None = None) -> dict:
    """The state model `current` (a run, or an ensemble: each member in OUT/member_i, and OUT an
    ensemble of them), fine-tuned for `steps` on `original`'s data plus every recorded rollout;
    returns each member's held-out errors (its eval.json) by member."""
    from gymnast.utils.settings import from_json
    from gymnast.world_model.ensemble import is_ensemble, member_paths
    from gymnast.world_model.state_model import write_state_ensemble
    from gymnast.world_model.train_state import StateTrainConfig, train_state_model

    pairs = list(zip(member_paths(original), member_paths(current), strict=True)) if is_ensemble(original) \
        else [(original, current)]
    reports, members = {}, []
    for i, (first, last) in enumerate(pairs):
        member = out / f"member_{i}" if len(pairs) > 1 else out
        saved = saved_settings(first)
        base = from_json(StateTrainConfig, saved["train"])
        settings = dataclasses.replace(base, steps=steps, checkpoint_every=min(base.checkpoint_every, steps),
                                       init=last, extra_data=(*base.extra_data, *recorded),
                                       **_logging_to(tracker))
        train_state_model(Path(saved["data"]), member, settings, resume=has_checkpoint(member), progress=progress)
        evaluation = member / "eval.json"
        reports[member.name] = read_json(evaluation) if evaluation.is_file() else None
        members.append(member)
    if len(members) > 1:
        write_state_ensemble(out, members)
    return reports


def _logging_to(tracker: tuple[str, ...] | None) -> dict:
    """The `tracker` setting of a fine-tuning run (none given: the original run's, kept)."""
    return {} if tracker is None else {"tracker": tracker}


def _fine_tuning(base, steps: int, current: Path, recorded: list[Path], **more):
    """A trainer's saved settings `base` turned into a short fine-tuning of `current` on its data plus
    the `recorded` rollouts: `steps` steps, the warm-up, checkpoints and logs scaled to fit them."""
    return dataclasses.replace(
        base, steps=steps, warmup_steps=min(base.warmup_steps, steps // 10), checkpoint_every=min(base.checkpoint_every, steps),
        log_every=min(base.log_every, steps), init=current, extra_data=(*base.extra_data, *recorded), **more)


def run_real_rl(config: DynaConfig, inputs: DynaInputs, out: Path, progress: bool) -> dict:
    """The comparison arm: its real success and training interactions at every round's boundary."""
    from gymnast.envs.kinds import REAL
    from gymnast.reward.spec import RewardSpec
    from gymnast.rl.config import RLRun
    from gymnast.rl.train import train_rl

    spec = RLRun(str(inputs.policy), REAL, RewardSpec.parse(config.real_reward), data=_str(inputs.data))
    summary = train_rl(spec, out, config.real_rl_config, resume=has_checkpoint(out), progress=progress)
    return {"curve": real_rl_curve(out, summary["curve"]), "real_interactions": summary["real_interactions"],
            "eval_real_interactions": summary["eval_real_interactions"], "wall_s": summary["wall_s"]}


def real_rl_curve(run: Path, curve: list[dict]) -> list[dict]:
    """A real-world RL run's learning curve (its summary's ``curve``) as Dyna's rows: real success
    with its interval and the real interactions spent on training by then (from its metrics)."""
    from gymnast.utils.metrics import read_metrics

    spent = {row["step"]: row["rollout/real_interactions"] for row in read_metrics(run)
             if "rollout/real_interactions" in row}
    return [{"step": point["step"], "success": point["eval/own_success"], "ci_low": point["eval/own_ci_low"],
             "ci_high": point["eval/own_ci_high"], "episodes": point["eval/own_episodes"],
             "real_interactions": spent.get(point["step"], 0)} for point in curve]


def summarise(config: DynaConfig, rounds: list[dict], real_rl: dict | None) -> dict:
    """summary.json: per round the real success (95% CI) and the real interactions, cumulative,
    by kind (training rollouts; evaluation and RL's checks, which measure rather than train)."""
    rows, spent, measured = [], 0, 0
    for row in rounds:
        collected, trained = row.get("rollouts", {}), row.get("rl", {})
        spent += collected.get("real_interactions", 0)
        measured += row["eval_real_interactions"] + trained.get("check_real_interactions", 0)
        judge_before = collected.get("judge_before", {})
        rows.append({
            "round": row.get("round", 0), "rl_steps": row.get("rl_steps", 0),
            **{key: row[key] for key in ("success", "ci_low", "ci_high", "episodes", "per_task")},
            "rollout_episodes": collected.get("episodes", 0), "rollout_successes": collected.get("successes", 0),
            "judge_fpr_on_rollouts": judge_before.get("real_fpr_whole_failures"),
            "judge_tpr_on_rollouts": judge_before.get("real_tpr"),
            "judge_heldout_real_fpr": row.get("judge", {}).get("real_fpr"),
            "real_interactions": spent, "measurement_real_interactions": measured})
    return {"rounds": rows, "real_rl": real_rl, "dyna_real_interactions": spent,
            "real_rl_real_interactions": None if real_rl is None else real_rl["real_interactions"],
            "tasks": config.rl.tasks, "eval_episodes_per_task": config.eval_episodes,
            "settings": dataclasses.asdict(config)}


def _evaluate(policy: Path, config: DynaConfig, report: Path) -> dict:
    """`gymnast eval` of `policy` in the real world; the record keeps its figures, not its episodes."""
    from gymnast.eval.actors import load_run_policy
    from gymnast.eval.evaluate import EvalConfig, evaluate

    size = load_run_policy(str(policy) if is_plugin(policy) else str(Path(policy).resolve())).config.image_size
    settings = EvalConfig(tasks=config.rl.tasks, episodes=config.eval_episodes, workers=config.workers,
                          runner=config.runner, env=EnvConfig(image_size=size, horizon=config.rl.evaluation_horizon))
    result = evaluate(str(policy), settings, report, progress=False)
    return {**{key: result[key] for key in ("success", "ci_low", "ci_high", "episodes", "successes", "per_task")},
            "eval_real_interactions": result["real_interactions"]}


def can_be_refit(wm: str | Path) -> bool:
    """Whether Dyna fine-tunes the world model `wm` each round: a gymnast run saves how it was
    trained; a world model of one's own does not, and is kept as given."""
    return not is_plugin(wm)


def _rl_record(summary: dict) -> dict:
    return {"imagined_start": summary.get("start_success"), "imagined_end": summary.get("end_success"),
            "check_real_interactions": summary["eval_real_interactions"] + summary["watch_real_interactions"],
            "wall_s": summary["wall_s"]}


def _str(path: Path | None) -> str | None:
    return None if path is None else str(path)
