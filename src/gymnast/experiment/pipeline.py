"""`gymnast experiment`: the papers' comparison on the real world, from data to report.

Stages, in order, each done once (`gymnast.experiment.stages`; a rerun skips finished ones):

1. ``collect``: expert demonstrations and failures recorded in the real world.
2. ``sft``: the SFT policy every arm starts from.
3. ``world_model``, ``judge``, ``state_model``, ``world_model_eval``: the world model, the learned
   judge (trained on real and re-imagined episodes, and with ``judge_rollouts`` on the SFT
   policy's own real rollouts, recorded first in ``judge_rollouts/``, and recorded again, or finished,
   if they are gone or cut short when a later stage refits the judge), the grounded state model
   whose reward head rewards one arm, and the world model's fidelity on held-out episodes.
   ``imagination``: the SFT policy's judged imagined rollouts against the same actions replayed
   in the real world (`gymnast.experiment.imagination`); ``signal``: whether GRPO's update in
   imagination is the one the real outcomes would give (`gymnast.experiment.practice_signal`).
4. ``arm_<name>``: Iter-SFT, the four RL arms and Dyna (`gymnast.experiment.arms`);
   ``equal_budget_<name>``: one small real budget spent three ways (`gymnast.experiment.equal_budget`).
5. ``eval_<name>``: every arm in the real world, ``eval_episodes`` per task from the evaluation
   seeds, Wilson intervals; then the SFT and world-model-RL policies under minor and major
   perturbations and with held-out instruction paraphrases.
6. ``worldgym``: imagined against real success over policies of different quality: the arms, the
   SFT run's earlier checkpoints and the SFT policy with growing action noise.
7. The report (always rewritten): summary.json, report.md, plots/.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

from gymnast.config import EnvConfig
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.lerobot_v3 import INFO_PATH
from gymnast.envs.parallel import kept_workers
from gymnast.envs.sim_vector import shared_simulator_processes
from gymnast.experiment.arms import ARMS, PERTURBATIONS, ROBUSTNESS_ARMS, arm, dyna_setup, rl_setup
from gymnast.experiment.config import ExperimentConfig
from gymnast.experiment.stages import Stages
from gymnast.reward.spec import RewardSpec
from gymnast.rl.evaluate import shared_evaluations
from gymnast.utils.atomic import read_json, write_json
from gymnast.utils.checkpoint import has_checkpoint
from gymnast.utils.device import resolve_device
from gymnast.utils.settings import from_json, saved_settings


def run_experiment(config: ExperimentConfig, out: Path, reuse: dict[str, Path] | None = None,
                   progress: bool = True) -> dict:
    """Runs (or finishes) the experiment in `out`; returns summary.json's content.

    Its stages build dozens of short-lived simulator envs (every arm's training, evaluations and
    replays): they pass their worker processes on instead of starting new ones (`shared_simulator_processes`).
    Every arm starts by evaluating the same SFT policy on the same seeds: that evaluation runs once
    (`gymnast.rl.evaluate.shared_evaluations`).
    """
    with shared_simulator_processes(), shared_evaluations():
        return _run_experiment(config, out, reuse, progress)


def _run_experiment(config: ExperimentConfig, out: Path, reuse: dict[str, Path] | None, progress: bool) -> dict:
    from gymnast.experiment.report.write import write_report

    config = config.resolved()
    resolve_device(config.device)  # a missing GPU is said now, not after the data is recorded
    out.mkdir(parents=True, exist_ok=True)
    _save_settings(out, config)
    stages = Stages(out, reuse)
    data, sft, wm, judge, state = _models(stages, config, out, progress)
    stages.run("imagination", lambda: _imagination(sft, wm, judge, config, out, progress), out / "imagination")
    stages.run("signal", lambda: _signal(sft, wm, RewardSpec.judge(judge), data, config, out / "signal", progress),
               out / "signal")
    stages.run("signal_state", lambda: _signal(sft, wm, RewardSpec("state", run=state), data, config,
                                               out / "signal_state", progress), out / "signal_state")
    policies = {"sft": sft}
    for spec in ARMS[1:]:
        policies[spec.name] = _train_arm(stages, spec.name, config, out, sft, wm, judge, state, data, progress)
    equal_budget = {}
    if config.equal_budget.rollouts_per_task:
        from gymnast.experiment.equal_budget import train_equal_budget

        equal_budget = train_equal_budget(stages, config, out / "equal_budget", sft, wm, judge, data, progress)
    if config.new_scenes.scenes_per_task:
        stages.run("new_scenes", lambda: _new_scenes(sft, wm, judge, config, out / "new_scenes", progress),
                   out / "new_scenes")
    # The real world as the dataset saw it, read only by an evaluation still to run.
    env = functools.cache(lambda: EnvConfig(image_size=_dataset_image_size(stages, config),
                                            horizon=config.rl.evaluation_horizon))
    # The arms are trained: their evaluations share one set of simulator processes.
    with kept_workers(config.workers, config.runner):
        for name, policy in policies.items():
            _evaluate(stages, f"eval_{name}", policy, config, out, config.eval_episodes, env, progress)
        for name, policy in equal_budget.items():
            _evaluate(stages, f"eval_equal_budget_{name}", policy, config, out, config.eval_episodes, env, progress)
        for name in ROBUSTNESS_ARMS:
            for perturb in PERTURBATIONS:
                _evaluate(stages, f"eval_{name}_{perturb}", policies[name], config, out, config.robustness_episodes,
                          env, progress, perturb=perturb)
            _evaluate(stages, f"eval_{name}_heldout", policies[name], config, out, config.robustness_episodes, env,
                      progress, instruction_split="heldout", sentences=config.sentences)
        stages.run("worldgym", lambda: _worldgym(stages, config, out, policies, wm, judge, env, progress))
    summary = write_report(out, stages, config)
    _track(out, config, summary)
    return summary


def _track(out: Path, config: ExperimentConfig, summary: dict) -> None:
    """The experiment's settings, each arm's real success and the report's plots, to the trackers
    of its RL arms (`--tracker`), as one run of its own in `out`."""
    from gymnast.utils.trackers import open_trackers

    trackers = open_trackers(config.rl.tracker, out, kind="experiment", config=dataclasses.asdict(config))
    for i, (name, row) in enumerate(summary["arms"].items()):
        trackers.log_metrics(i, {f"eval/{name}_{key}": row[key] for key in ("success", "ci_low", "ci_high")})
    for plot in sorted((out / "plots").glob("*.png")):
        trackers.log_image(f"plots/{plot.stem}", 0, plot)
    trackers.close()


def _models(stages: Stages, config: ExperimentConfig, out: Path, progress: bool
            ) -> tuple[Path, Path, Path, Path, Path]:
    """The dataset, SFT policy, world model, judge and state model, trained here or reused."""
    from gymnast.data.collect import collect
    from gymnast.policy.sft import train_sft
    from gymnast.reward.judges.train import train_judge
    from gymnast.world_model.train import train_world_model
    from gymnast.world_model.train_state import train_state_model

    def record() -> dict:
        return {"success": collect(config.collect, out / "data", progress)}

    stages.restore_dataset("collect", out / "data", lambda: _success_totals(record()["success"]),
                           stages.pending(_dataset_readers(config)), "the experiment's dataset",
                           lambda stage: _success_totals(stage["success"]))
    stages.run("collect", record, out / "data")
    data = stages.path("collect")
    stages.run("sft", lambda: _trained(train_sft, data, out / "sft", config.sft, progress), out / "sft")
    _check_freeze(stages.path("sft"), config.rl.freeze)
    stages.run("world_model", lambda: _trained(train_world_model, data, out / "world_model", config.world_model, progress),
               out / "world_model")
    wm = stages.path("world_model")

    def judge_stage() -> dict:
        target, settings, rollouts, recorded = out / "judge", config.judge, None, out / "judge_rollouts"
        if config.judge_rollouts:
            rollouts = _judge_rollouts(stages.path("sft"), config, recorded, progress)
            settings = dataclasses.replace(settings, extra_data=(*settings.extra_data, recorded))
        report = train_judge(data, target, settings, wm=wm, resume=has_checkpoint(target), progress=progress)
        return {"metrics": {k: v for k, v in report.items() if k.startswith(("real", "imagined"))}, "rollouts": rollouts}

    stages.run("judge", judge_stage, out / "judge")
    _restore_judge_rollouts(stages, config, out / "judge_rollouts", progress)
    stages.run("state_model", lambda: _trained(train_state_model, data, out / "state_model", config.state_model,
                                               progress), out / "state_model")
    stages.run("world_model_eval", lambda: _world_model_fidelity(wm, data, out, progress, config.device), out / "world_model_eval.json")
    return data, stages.path("sft"), wm, stages.path("judge"), stages.path("state_model")


def _dataset_readers(config: ExperimentConfig) -> list[str]:
    """The stages that read the collected dataset (the models', the signals' starts, the arms'
    keyframes and demonstrations, the equal budgets'); the evaluations and WorldGym after them
    read only its image size (`_dataset_image_size`), so an exported experiment resumed there
    does not record it again."""
    readers = ["world_model", "judge", "state_model", "world_model_eval", "signal", "signal_state",
               *(f"arm_{spec.name}" for spec in ARMS[1:])]
    if config.equal_budget.rollouts_per_task:
        readers += ["equal_budget_real_grpo", "equal_budget_imagined", "equal_budget_iter_sft"]
    return readers


def _success_totals(table: dict) -> dict:
    """A collection's success table (task -> behaviour -> [successes, episodes]) as totals."""
    cells = [cell for behaviours in table.values() for cell in behaviours.values()]
    return {"episodes": sum(episodes for _, episodes in cells), "successes": sum(successes for successes, _ in cells)}


def _dataset_image_size(stages: Stages, config: ExperimentConfig) -> int:
    """The frame size of the collected dataset: read in it (a reused dataset may have its own), or,
    in an exported experiment, which holds no dataset (experiment.export), the size its own
    collection was set to record."""
    path = stages.path("collect")
    if (path / INFO_PATH).is_file() or stages.record("collect")["reused"]:
        return EpisodeDataset(path).image_shape[0]
    return config.collect.env.image_size


def _restore_judge_rollouts(stages: Stages, config: ExperimentConfig, recorded: Path, progress: bool) -> None:
    """The judge's real rollouts made whole (`Stages.restore_dataset`) when the judge stage recorded
    them and a stage still to run refits the judge on them (Dyna's rounds, the equal budgets'
    imagined arm). A judge reused from another experiment learnt from that experiment's SFT policy's
    rollouts, in its directory: they are recorded there again, with its settings, when a refit here
    reads them."""
    refitting = (["arm_dyna"] if config.dyna.rounds > 1 else []) + \
        (["equal_budget_imagined"] if config.equal_budget.rollouts_per_task > 0 else [])
    judge = stages.record("judge")
    if not judge.get("rollouts") or not stages.pending(refitting):  # none recorded, or no refit still to run
        return
    maker, settings = stages, config
    if judge["reused"]:
        made_in = Path(judge["measured_in"])
        maker, recorded = Stages(made_in), made_in / "judge_rollouts"
        settings = dataclasses.replace(saved_experiment_config(made_in), workers=config.workers,
                                       runner=config.runner).resolved()
    maker.restore_dataset("judge", recorded, lambda: _judge_rollouts(maker.path("sft"), settings, recorded, progress),
                          True, "the judge's real rollouts", lambda record: record["rollouts"])


def _check_freeze(sft: Path, freeze: tuple[str, ...]) -> None:
    """The parts the RL arms freeze are the SFT policy's (a LeRobot policy names its own): said
    before the world model and the judge train, not hours later at the first arm."""
    if not freeze:
        return
    from gymnast.policy.load import load_policy
    from gymnast.rl.train import learning_parameters

    try:
        learning_parameters(load_policy(sft), freeze)
    except ValueError as error:
        raise ValueError(f"{sft}: {error}; give the experiment the parts to freeze with --freeze (none: --freeze "
                         "alone)") from error


def _new_scenes(sft: Path, wm: Path, judge: Path, config: ExperimentConfig, out: Path, progress: bool) -> dict:
    """Test-time practice: the SFT policy practises in imagination on each new scene, judged, and is
    measured there in the real world before and after (`gymnast.experiment.new_scenes`)."""
    from gymnast.envs.kinds import IMAGINED
    from gymnast.experiment.new_scenes import practice_settings, practise, scenes_for, totals
    from gymnast.rl.config import RLRun

    settings = config.new_scenes
    run = RLRun(str(sft), IMAGINED, RewardSpec.judge(str(judge)), wm=str(wm))
    rows = practise(run, practice_settings(config.rl, settings.steps, settings.starts_per_step),
                    scenes_for(config.new_scene_tasks, settings.scenes_per_task), out, progress)
    return {"scenes": rows, "totals": totals(rows)}


JUDGE_ROLLOUT_SEED = 300_000
"""Data seed of every task's first rollout recorded for the judge: scenes no other stage records
(Dyna's start at 100,000, the equal budgets' at 200,000)."""


def _judge_rollouts(sft: Path, config: ExperimentConfig, out: Path, progress: bool) -> dict:
    """The SFT policy's real rollouts that the judge learns from: sampled as RL samples them, played
    to the horizon so that a success stays in view (resumes an interrupted recording)."""
    from gymnast.eval.record import record_real_rollouts

    return record_real_rollouts(sft, config.tasks, config.judge_rollouts, JUDGE_ROLLOUT_SEED, config.rl.temperature,
                                config.rl.evaluation_horizon, config.workers, config.runner, out, progress,
                                terminate_on_success=False)


FIDELITY_KEYS = ("psnr_h1", "psnr_h8", "psnr_h32", "copy_last_psnr_h32", "moving_psnr_h32", "copy_last_moving_psnr_h32",
                 "ssim_h32", "episodes")


def _world_model_fidelity(wm: Path, data: Path, out: Path, progress: bool, device: str = "auto") -> dict:
    """`gymnast eval-wm` on the held-out episodes: open-loop fidelity and controllability, the
    first thing to look at when imagined practice does not carry over to the real world."""
    from gymnast.world_model.controllability import ControllabilityConfig
    from gymnast.world_model.data import split_episodes
    from gymnast.world_model.evaluate import WorldModelEvalConfig, evaluate_world_model, heldout_fraction

    fraction = heldout_fraction(wm)  # a run's, or the smallest of an ensemble's members
    if not split_episodes(EpisodeDataset(data).episodes, fraction)[1]:  # tiny datasets may hold out no scene
        return {"skipped": f"{data} has no scene held out from the world model (held-out fraction {fraction})"}
    settings = WorldModelEvalConfig(videos=2, controllability=ControllabilityConfig(scenes=4), device=device)
    report = evaluate_world_model(wm, data, out / "world_model_eval.json", settings, progress)
    control = report.get("controllability") or {}
    # A model of one frame per chunk is measured on the frames it imagines (eval-wm): each horizon at the next one.
    per_frame = (report.get("model") or {}).get("actions_per_frame", 1)
    return {**{key: report[key] for key in FIDELITY_KEYS if key in report}, "actions_per_frame": per_frame,
            "controllability": {key: control.get(key) for key in ("matched_psnr", "mismatched_psnr", "identification_accuracy")}}


def _imagination(sft: Path, wm: Path, judge: Path, config: ExperimentConfig, out: Path, progress: bool) -> dict:
    """The SFT policy's imagined rollouts, judged, against the same actions in the real world
    (`gymnast.experiment.imagination`): how far the arms that practise in imagination can trust it."""
    from gymnast.experiment.imagination import ImaginationConfig, imagination_brief, measure_imagination_runs
    from gymnast.reward.spec import RewardSpec

    settings = ImaginationConfig(tasks=config.tasks, episodes=config.worldgym_episodes, horizon=config.rl.horizon,
                                 workers=config.workers, runner=config.runner, seed=config.seed)
    report = measure_imagination_runs(sft, wm, RewardSpec.judge(judge), settings, out / "imagination", progress)
    return imagination_brief(report)


def _signal(sft: Path, wm: Path, reward: RewardSpec, data: Path, config: ExperimentConfig, out: Path,
            progress: bool) -> dict:
    """GRPO groups of the SFT policy sampled in imagination as the world-model arms sample them (the
    same kind of starts, from the dataset's episodes as `rl.keyframes` draws them, the same horizon,
    group size and temperature), scored by an arm's `reward`, against the real outcomes of the
    same actions (`gymnast.experiment.practice_signal`): would practice there push the policy the
    right way? Read over every task and over the weak tasks among them (``weak``)."""
    from gymnast.experiment.practice_signal import SignalConfig, batch_for, measure_signal_runs
    from gymnast.experiment.signal_report import signal_brief
    from gymnast.world_model.evaluate import heldout_fraction

    group = config.rl.group_size
    # The starts come from the scenes the world model held out; a dataset too small to hold any out
    # lends its others (with a warning), so a tiny experiment still measures.
    settings = SignalConfig(tasks=config.tasks, starts_per_task=config.signal_scenes,
                            task_starts=dict.fromkeys(config.weak_task_list, config.signal_weak_scenes), data=str(data),
                            keyframes=config.rl.keyframes, heldout_fraction=heldout_fraction(wm), group_size=group,
                            temperature=config.rl.temperature, horizons=(config.rl.horizon,),
                            batch=batch_for(group), workers=config.workers, runner=config.runner,
                            seed=config.seed)
    report = measure_signal_runs(sft, wm, reward, settings, out, progress)
    return {**signal_brief(report), "weak": signal_brief(report, config.weak_task_list)}


def _trained(train, data: Path, target: Path, settings, progress: bool) -> dict:
    """Runs a trainer that resumes from its own checkpoint when a previous attempt left one."""
    checkpoint = train(data, target, settings, resume=has_checkpoint(target), progress=progress)
    return {"checkpoint": str(checkpoint)}


def _train_arm(stages: Stages, name: str, config: ExperimentConfig, out: Path, sft: Path, wm: Path, judge: Path,
               state: Path, data: Path, progress: bool) -> Path:
    """Trains one arm (Iter-SFT, an RL arm or Dyna) in ``out/arms/<name>``; returns the directory of
    its final policy (Dyna's: its last round's RL run)."""
    from gymnast.experiment.iter_sft import train_iter_sft
    from gymnast.rl.train import train_rl

    target = out / "arms" / name
    spec = arm(name)

    def work() -> dict:
        if spec.dyna:
            return _dyna_arm(config, sft, wm, judge, data, target, progress)
        if not spec.is_rl:
            return {"imagined": train_iter_sft(sft, wm, judge, data, target, config, progress), "real_interactions": 0}
        run, rl = rl_setup(spec, config, sft, wm, judge, data, state)
        summary = train_rl(run, target, rl, resume=has_checkpoint(target), progress=progress)
        summary.pop("curve")
        return summary

    final = target / f"round_{config.dyna.rounds}" / "rl" if spec.dyna else target
    stages.run(f"arm_{name}", work, final)
    return stages.path(f"arm_{name}")


def _dyna_arm(config: ExperimentConfig, sft: Path, wm: Path, judge: Path, data: Path, target: Path,
              progress: bool) -> dict:
    """`gymnast dyna` in ``target``; its record counts the real interactions as the RL arms' do:
    the recorded rollouts train, the per-round evaluations and the watch only measure."""
    from gymnast.experiment.dyna import run_dyna

    settings, inputs = dyna_setup(config, sft, wm, judge, data)
    summary = run_dyna(settings, inputs, target, progress)
    last = summary["rounds"][-1]
    return {"run": str(target), "steps": config.rl.steps, "real_interactions": summary["dyna_real_interactions"],
            "eval_real_interactions": last["measurement_real_interactions"], "wall_s": summary["wall_s"]}


def _evaluate(stages: Stages, stage: str, policy: Path, config: ExperimentConfig, out: Path, episodes: int,
              env: Callable[[], EnvConfig], progress: bool, perturb: str = "none", instruction_split: str = "train",
              sentences: Path | None = None) -> dict:
    """A real-world evaluation of `policy` as a stage, in the real world `env()` gives; its record
    keeps the summary figures."""
    from gymnast.eval.evaluate import EvalConfig, evaluate

    def work() -> dict:
        settings = EvalConfig(tasks=config.tasks, episodes=episodes, perturb=perturb, instruction_split=instruction_split,
                              sentences=sentences, workers=config.workers, runner=config.runner,
                              videos_per_task=1 if perturb == "none" else 0,
                              env=dataclasses.replace(env()))
        report = evaluate(str(policy), settings, out / "eval" / f"{stage.removeprefix('eval_')}.json", progress)
        keep = ("success", "ci_low", "ci_high", "episodes", "successes", "per_task", "real_interactions", "videos")
        return {key: report[key] for key in keep}

    return stages.run(stage, work, out / "eval" / f"{stage.removeprefix('eval_')}.json")


def _worldgym(stages: Stages, config: ExperimentConfig, out: Path, policies: dict[str, Path], wm: Path, judge: Path,
              env: Callable[[], EnvConfig], progress: bool) -> dict:
    """Imagined and real success of the arms, of the SFT run's earlier checkpoints and of the SFT
    policy's noise ladder (`ExperimentConfig.worldgym_noise`), which spans the range of real success."""
    import math

    from gymnast.experiment.worldgym import Candidate, WorldGym, correlation, noise_ladder
    from gymnast.policy.load import load_policy

    paths = dict(policies) | earlier_sft_checkpoints(policies["sft"])
    # The arms and checkpoints are measured in the real world by `gymnast eval` (a stage each);
    # the noise ladder by WorldGym's own real rollouts, with the same protocol and seeds.
    real = {name: stages.record(f"eval_{name}") if stages.done(f"eval_{name}") else
            _evaluate(stages, f"eval_{name}", path, config, out, config.worldgym_episodes, env, progress)
            for name, path in paths.items()}
    candidates = [Candidate(name, load_policy(path), str(path)) for name, path in paths.items()]
    levels = (*config.worldgym_noise, *((math.inf,) if config.worldgym_random else ()))
    if levels:
        candidates += noise_ladder(policies["sft"], levels, config.seed, prefix="sft_")
    with WorldGym(wm, judge, config.tasks, config.worldgym_episodes, env(), config.workers, runner=config.runner) as gym:
        rows = gym.rows(candidates, real, progress)
    return {"policies": rows, **correlation([r["imagined"] for r in rows], [r["real"] for r in rows])}


def earlier_sft_checkpoints(sft: Path) -> dict[str, Path]:
    """The SFT run's checkpoints before its last (the SFT arm itself), which WorldGym measures too,
    by name (``sft_step_<step>``; a stage ``eval_sft_step_<step>`` each)."""
    checkpoints = sorted(path for path in (sft / "checkpoints").glob("[0-9]*") if path.is_dir())
    return {f"sft_step_{int(checkpoint.name)}": checkpoint for checkpoint in checkpoints[:-1]}


def _save_settings(out: Path, config: ExperimentConfig) -> None:
    """DIR/config.json: the resolved settings. A rerun with other settings would mix two
    experiments in one table, so it is refused. Settings an older version did not have yet (a new
    arm's) are taken from this run's, so an experiment started before an upgrade continues,
    running only what it lacks."""
    import json

    def as_json(settings: ExperimentConfig) -> dict:
        return json.loads(json.dumps(dataclasses.asdict(settings), default=str))  # paths as strings

    path = out / "config.json"
    if path.exists():
        try:
            saved = as_json(from_json(ExperimentConfig, _filled(_as_they_ran(read_json(path)),
                                                                as_json(config))))
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: not an experiment's settings this version can read ({error})") from error
        if _trackers_aside(saved) != _trackers_aside(as_json(config)):  # where it logs may change
            raise ValueError(f"{out} holds an experiment with other settings ({path}); use a new --out, the same "
                             f"preset or --resume")
    write_json(path, as_json(config))


def _trackers_aside(settings: dict) -> dict:
    """`settings` without the stages' `tracker` (where they log, not what they compute), at any depth."""
    return {key: _trackers_aside(value) if isinstance(value, dict) else value
            for key, value in settings.items() if key != "tracker"}


def _filled(saved: dict, current: dict) -> dict:
    """`saved` with the settings it lacks (at any depth) taken from `current`."""
    filled = dict(saved)
    for key, value in current.items():
        if key not in saved:
            filled[key] = value
        elif isinstance(value, dict) and isinstance(saved[key], dict):
            filled[key] = _filled(saved[key], value)
    return filled


def _as_they_ran(saved: dict) -> dict:
    """`saved` with the settings added since, as the experiment ran without them (not today's
    defaults): before cameras were a setting it recorded the views its collection did, the front
    camera unless it named others; before `judge_rollouts`, its judge learned from none; before
    `signal_weak_scenes`, the weak tasks took `signal_scenes` starts like the others; before
    `hold_steps`, its judges believed a single frame."""
    views = saved.get("collect", {}).get("env", {}).get("cameras", list(EnvConfig().cameras))
    ran = {"cameras": views, "judge_rollouts": 0, "signal_weak_scenes": saved.get("signal_scenes", 4), **saved}
    if "judge" in saved:
        ran["judge"] = {"hold_steps": 1, **saved["judge"]}
    return ran


def saved_experiment_config(out: Path) -> ExperimentConfig:
    """The settings the experiment in `out` was started with (DIR/config.json), for ``--resume``."""
    return from_json(ExperimentConfig, _as_they_ran(saved_settings(out)))
