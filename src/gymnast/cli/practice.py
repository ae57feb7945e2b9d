"""`gymnast` commands that practise: GRPO through one loop, Dyna's rounds and the headline experiment."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated, Literal

import tyro

from gymnast.cli.flags import GPUPreset, Preset, RLFlags
from gymnast.cli.settings import resolve
from gymnast.config import CameraNames
from gymnast.envs.kinds import EnvName, env_kind
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RL_PRESETS, RLConfig
from gymnast.utils.trackers import TrackerNames

TRACKED_STAGES = ("sft", "world_model", "judge", "state_model", "rl")
"""The experiment's settings of trainers, each with its `tracker`."""


def rl(
    out: Path,
    policy: Path | None = None,
    env: EnvName | None = None,
    reward: str | None = None,
    wm: Path | None = None,
    data: Path | None = None,
    robot_state: Path | None = None,
    reward_sees: Literal["own", "real", "imagined", "sim"] | None = None,
    reward_wm: Path | None = None,
    preset: GPUPreset = "full",
    resume: bool = False,
    config: Annotated[RLFlags, tyro.conf.arg(name="")] = RLFlags(),
) -> None:
    """Fine-tune a policy with GRPO in the world model (imagined), the software simulator or the real world.

    Args:
        out: run directory: checkpoints, metrics.jsonl, tensorboard/ (--tracker), videos/, summary.json.
        policy: the SFT (or RL) run or checkpoint to start from (required unless --resume); also lerobot:PATH
            (a LeRobot pretrained_model folder), or your own: python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG]
            (gymnast check-policy --help).
        env: where rollouts happen: imagined (in --wm), sim (the software simulator, --gap), real, or
            anchored (in the real world, the policy seeing it through --wm restarted from the real
            frame every --anchor-every actions: the imagined sight, cut short).
        reward: judge:RUN | state:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense, or all:REWARD+REWARD
            (success only where every one reads success, e.g. all:judge:RUN+state:RUN).
        wm: the world model run or ensemble (needed by --env imagined and --reward verified); or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help).
        data: dataset whose scenes are the start states (default: the one the policy was trained on).
        robot_state: with --env imagined, a state model (or ensemble) run stepped beside the world
            model, whose imagined robot state is given to a policy that reads one (observation.state).
        reward_sees: what the reward reads: own (the rollouts' own video; the default), or the same
            actions from the same starts replayed in another world: real (the real world's verdict
            on imagined actions, counted as real interactions) or imagined (the world model's
            re-imagining of real actions, --wm, or of imagined ones in --reward-wm); one rung of
            `gymnast ladder`.
        reward_wm: with --reward-sees imagined, another world model the reward's replays are imagined
            in: one that did not show the policy the frames it acted on (a run, or your own forms as --wm).
        preset: debug (seconds), demo (minutes), full or gpu (400 steps of 256 rollouts; docs/gpu.md).
        resume: continue the run in OUT from its last checkpoint, with the settings, policy, env,
            reward, world model and data saved there.
        config: the GRPO settings; each one left out keeps the preset's value.
    """
    from gymnast.rl.config import RLRun, reward_sight, saved_rl_settings
    from gymnast.rl.inputs import with_tasks_from_data
    from gymnast.rl.train import train_rl

    def saved() -> tuple[RLConfig, dict]:
        run_spec, settings = saved_rl_settings(out)
        return settings, {field.name: getattr(run_spec, field.name) for field in dataclasses.fields(run_spec)}

    # Parsed here, once: the library takes the env kind and the reward spec, never their names.
    settings, inputs = resolve(
        "rl", out, resume, RL_PRESETS[preset], overrides=dataclasses.asdict(config), saved=saved,
        inputs={"policy": policy, "env": None if env is None else env_kind(env),
                "reward": None if reward is None else RewardSpec.parse(reward), "wm": wm, "data": data,
                "robot_state": robot_state, "reward_sees": None if reward_sees is None else reward_sight(reward_sees),
                "reward_wm": reward_wm},
        required=("policy", "env", "reward"))
    run_spec = RLRun(**{name: str(value) if isinstance(value, Path) else value for name, value in inputs.items()})
    if not resume and config.tasks is None:  # the preset's tasks may not be in the data
        settings = with_tasks_from_data(run_spec, settings)
    summary = train_rl(run_spec, out, settings, resume=resume)
    summary.pop("curve")
    print(json.dumps(summary, indent=2))


def ladder(
    out: Path,
    policy: Path | None = None,
    wm: Path | None = None,
    judge: Path | None = None,
    state: Path | None = None,
    rungs: str | None = None,
    adopt: str | None = None,
    index: Path | None = None,
    preset: Literal["debug", "full"] = "full",
    resume: bool = False,
    config: Annotated[RLFlags, tyro.conf.arg(name="")] = RLFlags(),
) -> None:
    """Where learning dies between reality and imagination: the same GRPO recipe once per rung, each
    rung swapping one part (what the policy sees, what steps the rollout, who rewards, what the
    reward sees), every rung evaluated in the real world, with its reward's agreement with the real
    outcome at every step. Writes OUT/<rung>/ (each an RL run), OUT/summary.json, OUT/ladder.md,
    OUT/curves.png and OUT/agreement.png; rerunning continues where it stopped.

    Args:
        out: ladder directory.
        policy: the policy every rung starts from: an SFT run or checkpoint (required unless --resume);
            also lerobot:PATH (a LeRobot pretrained_model folder), or your own: python:MODULE:FACTORY[@ARG]
            or plugin:NAME[@ARG] (gymnast check-policy --help).
        wm: the world model of the imagined rungs (r2, r3, r4, r4s): a run or ensemble, or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help).
        judge: the judge run of the judged rungs (r1, r2, r4).
        state: the state model (or ensemble) run of the state rungs (r1s, r4s).
        rungs: the rungs to run now, in this order, comma-separated, of r0_real, r1_judge_real,
            r1s_state_real, r2_imagined_verdict, r3_imagined_sight, r4_imagined, r4s_imagined_state;
            all: every one. A later call may run others in the same OUT; the report covers them all.
            (default: all; with --adopt, none)
        adopt: rungs that ran elsewhere, RUNG=RUN comma-separated (e.g. r0_real=results/rl/my_real_run):
            each is linked in as the rung, not trained again, once it is shown to be the same
            experiment (the rung's env, reward and models, the ladder's GRPO recipe and starting
            policy; how it was evaluated may differ, and the report says so).
        index: also gather every ladder under this directory into INDEX/summary.json, nested by
            path (e.g. --out results/ladder/scarce/mt10 --index results/ladder).
        preset: debug (seconds; tests) or full (the recipe that learns on MT10, 100 evaluation
            seeds per task; docs/rl.md "Where learning dies").
        resume: continue the ladder in OUT with the settings and models saved there (also what a
            plain rerun does).
        config: the GRPO settings every rung shares; each one left out keeps the preset's value.
    """
    from gymnast.experiment.ladder import LADDER_PRESETS, LadderInputs, parse_rungs, run_ladder
    from gymnast.experiment.ladder_adopt import adopt_rung, parse_adoptions
    from gymnast.experiment.ladder_report import ladder_table, write_ladder_index
    from gymnast.utils.settings import from_json, saved_settings

    def saved() -> tuple[RLConfig, dict]:
        return from_json(RLConfig, saved_settings(out, "rl")), saved_settings(out, "inputs")

    settings, inputs = resolve(
        "ladder", out, resume or (out / "config.json").is_file(), LADDER_PRESETS[preset],
        overrides=dataclasses.asdict(config), saved=saved,
        inputs={"policy": policy, "wm": wm, "judge": judge, "state": state}, required=("policy",))
    models = LadderInputs(**{name: str(value) if value is not None else None for name, value in inputs.items()})
    if not (out / "config.json").is_file():
        from gymnast.utils.atomic import write_json

        write_json(out / "config.json", {"rl": dataclasses.asdict(settings), "inputs": dataclasses.asdict(models)})
    adoptions = parse_adoptions(adopt)
    for rung, run in adoptions.items():
        print(f"{rung.name}: the run {run}, adopted as {adopt_rung(out, rung, run, models.run_of(rung), settings)}")
    to_train = parse_rungs(rungs) if rungs else () if adoptions else parse_rungs("all")
    summary = run_ladder(models, settings, to_train, out)
    print(ladder_table(summary))
    if index is not None:
        write_ladder_index(index)
    print(f"report: {out / 'ladder.md'}")


def dyna(
    out: Path,
    policy: Path | None = None,
    wm: Path | None = None,
    judge: Path | None = None,
    state: Path | None = None,
    data: Path | None = None,
    preset: Preset = "full",
    resume: bool = False,
    rounds: int | None = None,
    rollouts_per_task: int | None = None,
    record: Literal["rollouts", "plans"] | None = None,
    recipe: Path | None = None,
    steps: int | None = None,
    eval_episodes: int | None = None,
    tasks: str | None = None,
    keyframes: str | None = None,
    horizon: int | None = None,
    eval_horizon: int | None = None,
    practice_from_rollouts: bool | None = None,
    judge_steps: int | None = None,
    state_steps: int | None = None,
    wm_steps: int | None = None,
    workers: int | None = None,
    runner: str | None = None,
    real_rl: bool | None = None,
    tracker: TrackerNames | None = None,
) -> None:
    """World-Gymnast's loop: RL in imagination, a few counted real rollouts of the new policy, the
    world model and the reward model (judge or state model) fine-tuned on them, a real evaluation;
    repeated. Writes OUT/round_k/, OUT/summary.json, OUT/dyna.md (table) and OUT/dyna.png (real
    success against real interactions), beside RL in the real world with the same settings.
    Rerunning skips what finished.

    Args:
        out: run directory.
        policy: the SFT (or RL) run to start from (required unless --resume); also lerobot:PATH (a LeRobot
            pretrained_model folder), or your own: python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast
            check-policy --help).
        wm: the world-model run imagined RL starts in; fine-tuned every round; or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help) (imagined in as given,
            not fine-tuned).
        judge: the judge run that rewards imagined RL; fine-tuned every round (this or --state).
        state: instead of a judge, a state-model run or ensemble (`gymnast train-state`,
            `gymnast make-ensemble`) whose reward head rewards imagined RL; every member fine-tuned
            every round.
        data: dataset whose scenes imagined RL starts from (default: the one the policy was trained on).
        preset: debug (seconds; tests), demo (minutes) or full.
        resume: continue the run in OUT with the settings and inputs saved there.
        rounds: rounds of the loop (default: the preset's).
        rollouts_per_task: real episodes recorded per task and round (default: the preset's).
        record: what those episodes are: rollouts (the policy acting in the real world) or plans (its
            plans made closed loop in the round's world model, executed for real: the actions the
            model imagines succeeding where they fail) (default: the preset's, rollouts).
        recipe: an RL run or a ladder directory whose GRPO settings every round's RL uses instead of
            the preset's (e.g. the ladder's, to set the loop beside its rungs); the rounds' steps,
            evaluations and watch stay the loop's; --tasks and the other flags still apply.
        steps: RL steps in imagination per round (default: the preset's).
        eval_episodes: real evaluation episodes per task after each round, and the round's imagined RL
            evaluates on the same seeds (default: the preset's).
        tasks: tasks trained and evaluated on (default: the preset's).
        keyframes: where in the start episodes practice begins (see `gymnast rl --help`; default: the preset's).
        horizon: actions per imagined rollout, e.g. 20 for short segments (default: the preset's).
        eval_horizon: actions per real episode, recorded or evaluated (0: --horizon; with segments,
            the task's 150).
        practice_from_rollouts: rounds after the first practise from the previous round's real
            rollouts instead of --data (default: the preset's, off).
        judge_steps: fine-tuning steps of the judge per round; 0 keeps the given one (default: the preset's).
        state_steps: fine-tuning steps of the state model per round; 0 keeps the given one (default: the preset's).
        wm_steps: fine-tuning steps of the world model per round; 0 keeps the given one (default: the preset's).
        workers: simulator processes (default: the preset's).
        runner: where they run: local, ray or ray:ADDRESS (default: the preset's, local).
        real_rl: also run RL in the real world for comparison (default: the preset's, on).
        tracker: where every round's trainers, the real-world arm and the rounds' figures also log: none,
            or any of tensorboard and wandb, comma-separated (default: the preset's RL setting).
    """
    from gymnast.experiment.dyna import DYNA_PRESETS, DynaInputs, run_dyna, saved_dyna_settings, with_recipe
    from gymnast.experiment.dyna_report import dyna_table

    if recipe is not None and resume:
        raise ValueError("--recipe starts a new run; --resume continues with the settings saved in --out: give one")
    base = with_recipe(DYNA_PRESETS[preset], recipe, steps) if recipe is not None else DYNA_PRESETS[preset]

    def saved():
        config, inputs = saved_dyna_settings(out)
        return config, dataclasses.asdict(inputs)

    config, inputs = resolve(
        "dyna", out, resume, base,
        inputs={"policy": policy, "wm": wm, "judge": judge, "state": state, "data": data},
        overrides={"rounds": rounds, "rollouts_per_task": rollouts_per_task, "record": record, "rl.steps": steps,
                   "eval_episodes": eval_episodes, "rl.tasks": tasks, "rl.keyframes": keyframes, "rl.horizon": horizon,
                   "rl.eval_horizon": eval_horizon, "practice_from_rollouts": practice_from_rollouts,
                   "judge_steps": judge_steps, "state_steps": state_steps, "wm_steps": wm_steps, "workers": workers,
                   "runner": runner, "real_rl": real_rl, "rl.tracker": tracker}, saved=saved, required=("policy", "wm"))
    summary = run_dyna(config, DynaInputs(**inputs), out)
    print(dyna_table(summary))
    print(f"summary: {out / 'summary.json'}, plot: {out / summary['plot']}")


def experiment(
    out: Path,
    preset: GPUPreset = "full",
    resume: bool = False,
    reuse: Annotated[list[str], tyro.conf.UseAppendAction] = [],  # noqa: B006 (read by tyro, never mutated)
    workers: int | None = None,
    sentences: Path | None = None,
    runner: str | None = None,
    device: str | None = None,
    cameras: CameraNames | None = None,
    judge_rollouts: int | None = None,
    demos_per_task: int | None = None,
    freeze: tuple[str, ...] | None = None,
    tracker: TrackerNames | None = None,
    status: bool = False,
    report: bool = False,
) -> None:
    """The headline comparison: data, SFT, world model, judge, state model, eight arms, real-world
    evaluation and the WorldGym check, then OUT/report.md, OUT/summary.json and OUT/plots/.
    Rerunning the same command skips the stages that finished and continues an interrupted one.

    Args:
        out: experiment directory.
        preset: debug (a minute; tests), demo (a few tasks, what `make demo` runs), full (MT10) or gpu
            (MT10 at the papers' budget, for one GPU and its host's cores; docs/gpu.md).
        resume: continue the experiment in OUT with the settings saved there (whatever its preset).
        reuse: a stage to take from an earlier run instead of running it, as STAGE=DIR (collect=DATASET,
            sft=RUN, world_model=RUN, judge=RUN, state_model=RUN or an ensemble of them); repeat for
            several, e.g. --reuse collect=data/mt10 --reuse world_model=runs/wm_full. The world model
            may be one of your own: world_model=python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG]
            (imagined in as given; Dyna does not refit it).
        workers: simulator processes (default: the preset's, one per core on 2 cores).
        sentences: a file of `task: sentence` lines, your own wording of the tasks: the language
            check gives the policies these instead of the held-out paraphrases.
        runner: where they run: local, ray or ray:ADDRESS (default: the preset's, local).
        device: where the models train, imagine and judge: auto (CUDA when torch sees a GPU, else the
            CPU), cpu, cuda or cuda:N; --resume may change it.
        cameras: the views recorded and seen side by side by the policy, the world model and the
            judges, e.g. front or front,gripper (default: the preset's, front,gripper,hand).
        judge_rollouts: real rollouts per task of the SFT policy, played past any success, that the
            judge also learns from (its near misses; counted in summary.json); default: the preset's.
        demos_per_task: expert demonstrations per task the SFT policy learns from (default: the
            preset's, 10); the world model and the judge still learn from the whole dataset. 2 is
            the data-scarce regime (results/sft/scarce: SFT at 15-40% on MT10).
        freeze: parts of the policy the RL arms leave as SFT made them, by parameter-name prefix
            (default: the preset's, vision: the embedded policies' image encoder; a LeRobot
            policy's are its own, e.g. model.backbone; none: `--freeze` alone).
        tracker: where every stage's trainer and the report's figures and plots also log: none, or any
            of tensorboard and wandb, comma-separated (default: each stage's own; RL's is tensorboard).
        status: print where the experiment in OUT stands (the stages finished with their wall times,
            the one under way with its newest checkpoint, those still to run) and exit; nothing runs.
        report: write OUT/report.md and OUT/summary.json from the stages finished so far (an
            experiment under way: its figures so far and the stages still to run) and exit; nothing runs.
    """
    from gymnast.experiment.config import EXPERIMENT_PRESETS
    from gymnast.experiment.pipeline import run_experiment, saved_experiment_config

    if status:
        from gymnast.experiment.status import experiment_status, format_status

        if not (out / "config.json").is_file():
            raise FileNotFoundError(f"--status: {out} holds no experiment (no config.json there)")
        print(format_status(out, experiment_status(out, saved_experiment_config(out))))
        return
    if report:
        from gymnast.experiment.status import report_so_far

        summary = report_so_far(out)
        left = len(summary["stages_to_run"])
        print(f"report: {out / 'report.md'}" + (f" ({left} stages still to run)" if left else ""))
        return
    from gymnast.experiment.report.write import format_table
    from gymnast.experiment.stages import parse_reuse

    config, _ = resolve("experiment", out, resume, EXPERIMENT_PRESETS[preset],
                        overrides={"workers": workers, "sentences": sentences, "runner": runner, "device": device,
                                   "cameras": cameras, "judge_rollouts": judge_rollouts,
                                   "sft.demos_per_task": demos_per_task, "rl.freeze": freeze,
                                   **{f"{stage}.tracker": tracker for stage in TRACKED_STAGES}},
                        inputs={}, saved=lambda: (saved_experiment_config(out), {}))
    summary = run_experiment(config, out, parse_reuse(reuse))
    print(format_table(summary))
    print(f"report: {out / 'report.md'}")
