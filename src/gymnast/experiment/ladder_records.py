"""What the ladder's report reads from each rung's run: its real success at every evaluation, how
its reward agreed with the truth at every step, the watch, and the real interactions it spent.

A rung, and a fix arm that is a `gymnast rl` run, is read from its RUN/metrics.jsonl; a fix arm
that is a Dyna loop (`gymnast dyna`, OUT/fixed_<lever> holding its rounds) from its rounds'
evaluations and their RL runs, its steps counted across rounds. Either way a run still under way
reports what it has, and says whether it finished.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from gymnast.envs.kinds import IMAGINED
from gymnast.experiment.rungs import FIXED, Rung
from gymnast.experiment.stages import Stages
from gymnast.rl.config import RLConfig, RLRun
from gymnast.utils.metrics import read_metrics
from gymnast.utils.settings import saved_settings

TRUTH = ("agreement", "false_success", "missed_success", "truth_success", "truth_signal", "truth_rollouts")
"""The ``reward/`` metrics of each step that `agreement_by_step` keeps."""
WATCH = ("agreement", "false_success", "imagined_success", "real_success")
"""The ``eval/watch_`` metrics kept at each watch."""
SPENT = (("real_interactions", "rollout/real_interactions"), ("truth_real_interactions", "reward/truth_real_interactions"),
         ("watch_real_interactions", "eval/watch_real_interactions"), ("eval_real_interactions", "eval/real_interactions"))
"""Real interactions a run counts (its largest value: the counters are cumulative), by kind."""


def rung_record(rung: Rung, run: Path, steps: int) -> dict | None:
    """Rung `rung`'s figures from its run directory, or None before its first evaluation. A rung
    adopted from a run made elsewhere (`gymnast.experiment.ladder_adopt`: OUT/<rung> links to it)
    names that run."""
    record = dyna_record(rung, run) if is_dyna(run) else _rl_record(rung, run, steps)
    if record is not None and run.is_symlink():
        adopted = os.readlink(run)
        record = {**record, "what": f"{record['what']} (adopted: the run {adopted})", "adopted_from": adopted}
    return record


def _rl_record(rung: Rung, run: Path, steps: int) -> dict | None:
    lines = read_metrics(run)
    # A rung in the real world evaluates itself there ("own"); the others also in the real world.
    real = "eval/own" if rung.env.real_sight else "eval/real"
    curve = [_evaluation(line, real) for line in lines if f"{real}_success" in line]
    if not curve:
        return None
    last, done = curve[-1], _steps_done(lines)
    return _record(rung, curve, _spent(lines), done, done >= steps and last["step"] >= steps, *_truth_and_watch(lines))


def dyna_record(rung: Rung, run: Path) -> dict | None:
    """A Dyna loop's figures in a rung's form: its real evaluation before the first round and after
    each (round k at step k x its steps a round) as the curve, every round's RL truth and watch at
    their steps across rounds, and as training's real interactions its rounds' recorded episodes."""
    settings = saved_settings(run, "dyna")
    per_round, rounds = settings["rl"]["steps"], settings["rounds"]
    loop = Stages(run)
    if not loop.done("round_0_eval"):
        return None
    evaluations = [(0, loop.record("round_0_eval"))]
    by_step, watch, done = [], [], 0
    spent = {"real_interactions": 0, "truth_real_interactions": 0, "watch_real_interactions": 0,
             "eval_real_interactions": evaluations[0][1]["eval_real_interactions"]}
    for k in range(1, rounds + 1):
        here, offset = Stages(run / f"round_{k}"), (k - 1) * per_round
        lines = [{**line, "step": line["step"] + offset} for line in read_metrics(run / f"round_{k}" / "rl")] \
            if (run / f"round_{k}" / "rl" / "metrics.jsonl").exists() else []
        truth, watched = _truth_and_watch(lines)
        by_step, watch = by_step + truth, watch + watched
        done = max(done, _steps_done(lines))
        used = _spent(lines)  # each round's RL run counts from 0
        for key in ("truth_real_interactions", "watch_real_interactions"):
            spent[key] += used[key]
        if here.done("rollouts"):
            spent["real_interactions"] += here.record("rollouts")["real_interactions"]
        if here.done("eval"):
            evaluations.append((k * per_round, here.record("eval")))
            spent["eval_real_interactions"] += evaluations[-1][1]["eval_real_interactions"]
    curve = [{"step": step, **{key: result[key] for key in ("success", "ci_low", "ci_high", "episodes")},
              "tasks": {task: figures["success"] for task, figures in result["per_task"].items()}}
             for step, result in evaluations]
    return _record(rung, curve, spent, done, len(evaluations) == rounds + 1, by_step, watch)


def _record(rung: Rung, curve: list[dict], spent: dict, done: int, finished: bool, by_step: list[dict],
            watch: list[dict]) -> dict:
    last = curve[-1]
    return {"what": rung.what, "env": rung.env.name, "reward": rung.reward,
            "reward_sees": rung.sees.name if rung.sees else "own",
            "success": last["success"], "ci_low": last["ci_low"], "ci_high": last["ci_high"],
            "episodes": last["episodes"], "step": last["step"], "start_success": curve[0]["success"],
            **spent, "steps_done": done, "finished": finished,
            "agreement_by_step": by_step, "curve": curve, "watch": watch}


def _truth_and_watch(lines: list[dict]) -> tuple[list[dict], list[dict]]:
    """Per step, how the reward agreed with the real outcome; per watch, what it found."""
    by_step = [{"step": line["step"], **{name: line[f"reward/{name}"] for name in TRUTH if f"reward/{name}" in line},
                "verdict_success": line.get("rollout/success")}
               for line in lines if "reward/truth_rollouts" in line]
    watch = [{"step": line["step"], **{name: line[f"eval/watch_{name}"] for name in WATCH if f"eval/watch_{name}" in line}}
             for line in lines if "eval/watch_real_success" in line]
    return by_step, watch


def _spent(lines: list[dict]) -> dict:
    return {key: max([line[name] for line in lines if name in line], default=0) for key, name in SPENT}


def _steps_done(lines: list[dict]) -> int:
    return max((line["step"] for line in lines if "train/lr" in line), default=0)


def _evaluation(line: dict, prefix: str) -> dict:
    tasks = {key.removeprefix(f"{prefix}_success/"): value for key, value in line.items()
             if key.startswith(f"{prefix}_success/")}
    return {"step": line["step"], "success": line[f"{prefix}_success"], "ci_low": line[f"{prefix}_ci_low"],
            "ci_high": line[f"{prefix}_ci_high"], "episodes": line[f"{prefix}_episodes"], "tasks": tasks}


def is_dyna(run: Path) -> bool:
    """Whether `run` is a Dyna loop (its config.json holds ``dyna`` settings), not an RL run."""
    return (run / "config.json").is_file() and "dyna" in saved_settings(run)


NOT_THE_RECIPE = frozenset({
    "eval_every", "eval_episodes", "eval_horizon", "real_eval", "truth_groups", "watch_every", "watch_rollouts",
    "video_every", "checkpoint_every", "tracker", "workers", "device", "runner", "micro_batch", "remember_vision"})
"""RL settings that say how a run is evaluated, watched, logged or computed, not what it learns
(`micro_batch` accumulates the same gradient; `remember_vision` reuses the same tokens)."""


def recipe_changes(run: RLConfig, recipe: RLConfig) -> list[str]:
    """The names of the GRPO settings in which `run` differs from the ladder's `recipe`, those in
    `NOT_THE_RECIPE` aside."""
    return [field.name for field in dataclasses.fields(RLConfig)
            if field.name not in NOT_THE_RECIPE and getattr(run, field.name) != getattr(recipe, field.name)]


def fixed_arms(out: Path) -> list[Rung]:
    """OUT/fixed and every OUT/fixed_<lever> as rungs, by name: an RL run whose settings its
    config.json holds (any env, reward and lever a user mends the broken rung with), or a Dyna loop."""
    arms = []
    # A fix may be a world model or a policy of its own (one refit on what the ladder's got wrong, one
    # taught the imagined sight): named where it is not the ladder's.
    saved = saved_settings(out) if (out / "config.json").is_file() else {}
    ladder = saved.get("inputs", {})
    recipe = _grpo_settings(saved["rl"]) if "rl" in saved else None  # the arms' levers are read against it
    for where in sorted(out.glob(f"{FIXED.name}*")):
        if not (where / "config.json").is_file() or (where.name != FIXED.name and not where.name.startswith("fixed_")):
            continue
        if is_dyna(where):
            arms.append(_dyna_arm(where, ladder.get("policy")))
            continue
        arm = saved_settings(where)
        run = RLRun.from_json(arm["run"])
        model = f", imagined in {run.wm}" if run.wm and run.wm != ladder.get("wm") else ""
        sees = f", the reward seeing {run.reward_sees}" if run.reward_sees else ""
        other = f" in {run.reward_wm}" if run.reward_wm else ""
        start = _from_policy(run.policy, ladder.get("policy"))
        lever = ""
        if recipe is not None:
            settings = _grpo_settings(arm["rl"])
            lever = "".join(f" --{name.replace('_', '-')} {_flag(getattr(settings, name))}"
                            for name in recipe_changes(settings, recipe))
        data = f" --data {run.data}" if run.data else ""  # starts from another dataset's scenes or keyframes
        what = f"a fix: --env {run.env}{model} --reward {run.reward}{lever}{data}{sees}{other}{start}"
        arms.append(Rung(where.name, run.env, str(run.reward), run.reward_sees, what, bool(start)))
    return arms


def _grpo_settings(saved: dict) -> RLConfig:
    """The GRPO settings a config.json's ``rl`` section keeps (a ladder's recipe, or a run's)."""
    return RLConfig(**RLConfig.upgrade_saved(saved))


def _flag(value) -> str:
    """A setting as the command line writes it."""
    return ",".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)


def _from_policy(policy: str | Path, ladder_policy: str | None) -> str:
    """", from POLICY" where an arm starts from another policy than the ladder's rungs, else nothing."""
    return f", from {policy}" if ladder_policy and str(policy) != ladder_policy else ""


def _dyna_arm(where: Path, ladder_policy: str | None) -> Rung:
    from gymnast.experiment.dyna import saved_dyna_settings

    config, inputs = saved_dyna_settings(where)
    start = _from_policy(inputs.policy, ladder_policy)
    kind = inputs.reward_kind
    refit = [name for name, steps in (("the world model", config.wm_steps),
                                      ("the judge" if kind == "judge" else "the state model", config.reward_steps(kind)))
             if steps]
    rounds = f"gymnast dyna, {config.rounds} rounds of {config.rl.steps} steps in imagination"
    if not refit:  # the loop's rounds without its refits: what the rounds alone do
        return Rung(where.name, IMAGINED, kind, None, f"a control: {rounds}, nothing refit between them{start}",
                    bool(start))
    return Rung(where.name, IMAGINED, kind, None,
                f"a fix: {rounds}, each recording {config.rollouts_per_task} real {config.record} a task that "
                f"{' and '.join(refit)} {'are' if len(refit) > 1 else 'is'} refit on{start}", bool(start))
