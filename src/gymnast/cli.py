"""The `gymnast` command: one subcommand per job, each a thin call into the library."""

from __future__ import annotations

import dataclasses
import logging
import sys
from pathlib import Path
from typing import Annotated, Literal

import tyro

import gymnast  # noqa: F401  (sets MUJOCO_GL before anything imports mujoco)
from gymnast.cli_models import (KeyFlags, Preset, eval_judge, eval_wm, experiment, feature_keys, imagination,
                                key_overrides, make_ensemble, object_fidelity, practice_summary, rl, rl_signal,
                                serve_judge, train_judge, train_state, train_wm, worldgym)
from gymnast.cli_settings import resolve, saved_inputs
from gymnast.config import CameraNames, EnvConfig
from gymnast.data.frames import Fit
from gymnast.data.collect import CollectConfig
from gymnast.data.summary import format_success_table
from gymnast.eval.evaluate import EvalConfig


def collect(
    out: Path,
    config: Annotated[CollectConfig, tyro.conf.arg(name="")] = CollectConfig(),
    policy: Path | None = None,
    temperature: float = 0.0,
    imagine_with: Path | None = None,
) -> None:
    """Record scripted episodes (experts, noisy experts, failures), or a learned policy's own
    rollouts, into a LeRobot v3.0 dataset.

    Rerunning the same command resumes: episodes already in OUT are skipped.

    Args:
        out: dataset directory (created if missing).
        config: what to record.
        policy: an SFT/RL run directory: record its rollouts (behaviour policy-<tag>, greedy plus the
            --noise levels, no failure episodes) instead of the scripted behaviours.
        temperature: with --policy, sample the action tokens at this temperature (0: greedy).
        imagine_with: with --policy, a world-model run: the policy plans each episode closed loop in
            it from the scene's first frame and the real world executes the plan, so that every
            episode labels an imagined rollout with its real outcome (judge data for
            `gymnast train-judge --wm` on the same world model).
    """
    if policy is not None:
        from gymnast.eval.record import record_policy

        table = record_policy(policy, config, out, temperature=temperature, imagine_with=imagine_with)
    elif temperature or imagine_with:
        raise ValueError("--temperature and --imagine-with apply to a learned policy; give --policy RUN too")
    else:
        from gymnast.data.collect import collect as run_collect

        table = run_collect(config, out)
    print(format_success_table(table))
    print(f"dataset: {out}")


def evaluate_command(
    policy: str,
    out: Path,
    config: Annotated[EvalConfig, tyro.conf.arg(name="")] = EvalConfig(),
) -> None:
    """Evaluate a policy in the real world on held-out seeds: success per task with 95% CIs.

    Args:
        policy: an SFT/RL run directory (its newest checkpoint), 'expert' for the scripted reference, or
            lerobot:PATH for a LeRobot pretrained_model folder (acts in this process: --workers 1).
        out: JSON report (per-episode records included); videos are saved beside it in <name>_videos/.
        config: tasks, episodes, perturbation, gap and workers.
    """
    from gymnast.eval.evaluate import evaluate, format_summary
    from gymnast.policy.load import is_lerobot, load_policy

    # A LeRobot folder is no run directory for the workers to load: it acts in this process.
    report = evaluate(load_policy(policy) if is_lerobot(policy) else policy, config, out)
    print(format_summary(report))
    print(f"report: {out}")


def sft(
    out: Path,
    data: Path | None = None,
    preset: Preset = "full",
    resume: bool = False,
    demos_per_task: int | None = None,
    steps: int | None = None,
    vision: Literal["cnn", "efficientnet"] | None = None,
    tasks: str | None = None,
    seed: int | None = None,
    camera: str | None = None,
    cameras: CameraNames = (),
    policy_type: Literal["tokens", "flow"] | None = None,
    robot_state: bool | None = None,
    fit: Fit | None = None,
    device: str | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Behaviour-clone a VLA on N successful expert demonstrations per task.

    Args:
        out: run directory: checkpoints, metrics.jsonl, config.json.
        data: dataset directory (from `gymnast collect`); with --resume, the run's own.
        preset: debug (seconds), demo (minutes) or full (the default policy).
        resume: continue the run in OUT from its last checkpoint, with the settings and data saved there.
        demos_per_task: override the preset's demonstrations per task.
        steps: override the preset's optimizer steps.
        vision: override the image encoder.
        tasks: restrict to these tasks (comma-separated).
        seed: override the seed.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        cameras: several dataset cameras the policy sees side by side, the primary first (e.g.
            front,gripper); saved with the policy, so eval and rl render the same views. Default: --camera alone.
        policy_type: the policy family: tokens (the tokenized VLA, the default) or flow (the
            flow-matching VLA of VLA-RFT). Saved with the checkpoint; rl and eval read it there.
        robot_state: True: the policy also reads the robot's state (the dataset's observation.state,
            e.g. hand xyz and gripper); eval and rl give it the simulator's, imagination a state model's.
        fit: how frames that are not the model's square size are fitted: resize (squash the whole
            frame) or crop (the central square); saved with the run.
        device: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N; --resume may change it.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.policy.sft import SFT_PRESETS, saved_sft_config, train_sft

    config, inputs = resolve(
        "sft", out, resume, SFT_PRESETS[preset], inputs={"data": data}, required=("data",),
        overrides={"demos_per_task": demos_per_task, "steps": steps, "tasks": tasks, "seed": seed,
                   "vla.vision": vision, "camera": camera, "cameras": cameras or None, "policy": policy_type,
                   "robot_state": robot_state, "fit": fit, "device": device,
                   **key_overrides(keys)},
        saved=lambda: (saved_sft_config(out), saved_inputs(out, "data")))
    checkpoint = train_sft(inputs["data"], out, config, resume=resume)
    print(f"policy: {checkpoint}")


def inspect(
    data: Path,
    sheet: Path | None = None,
    episodes: int = 10,
    camera: str | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Summarise a dataset (v3.0 or v2.1): episodes, the features read, success by task and behaviour,
    codec error. A dataset whose features are named otherwise gets the candidates for the actions,
    the states and the cameras instead, and the flags that read them.

    Args:
        data: dataset directory.
        sheet: also write a PNG contact sheet (first, middle and last frame of a few episodes).
        episodes: how many episodes the contact sheet shows.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state).
    """
    from gymnast.data.features import FeatureNotFound
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.data.summary import describe_candidates, describe_dataset, write_episode_sheet

    try:
        dataset = EpisodeDataset(data, camera, keys=feature_keys(keys))
    except FeatureNotFound:  # the usual case of a dataset published elsewhere: say what to pass
        print(describe_candidates(data, feature_keys(keys), camera))
        return
    print(describe_dataset(dataset))
    if sheet is not None:
        print(f"contact sheet: {write_episode_sheet(dataset, sheet, episodes)}")


def contact_sheet(
    out: Path = Path("docs/mt10_contact_sheet.png"),
    tasks: str = "mt10",
    seed: int = 0,
    gap: str = "none",
    env: EnvConfig = EnvConfig(),
) -> None:
    """Render the first frame of every task, with each object's size in pixels.

    Args:
        out: PNG to write; a JSON of object pixel counts is written beside it.
        tasks: task names and/or sets.
        seed: data seed of the frames.
        gap: which world to show (none = the real world).
        env: camera and image size.
    """
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.envs.visibility import write_task_sheet

    print(f"contact sheet: {write_task_sheet(out, resolve_tasks(tasks), seed, gap, env)}")


def gap_report(
    out: Path = Path("docs/sim_gap.json"),
    tasks: str = "mt10",
    episodes: int = 10,
    levels: tuple[str, ...] = ("mild", "strong"),
    workers: int = 2,
    runner: str = "local",
    first_seed: int = 0,
    env: EnvConfig = EnvConfig(),
) -> None:
    """Measure each sim-to-real gap level: expert success drop, open-loop divergence of replays.

    Args:
        out: JSON file with the per-level summary and per-episode records (and a .md beside it).
        tasks: task names and/or sets.
        episodes: seeds per task.
        levels: gap levels to measure.
        workers: parallel processes.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        first_seed: first data seed.
        env: camera, image size and horizon.
    """
    from gymnast.envs.gap_report import format_level, measure_gap_levels, write_gap_report
    from gymnast.envs.tasks import resolve_tasks

    report = measure_gap_levels(resolve_tasks(tasks), episodes, levels, env, workers, first_seed, runner=runner)
    for level, result in report["levels"].items():
        print(format_level(level, result["overall"]))
    print(f"report: {out} and {write_gap_report(out, report)}")


def tasks(task_set: str = "mt10", split: str = "train") -> None:
    """List tasks with their instruction paraphrases.

    Args:
        task_set: task names and/or sets (mt10, mt50).
        split: train or heldout paraphrases.
    """
    from gymnast.envs.instructions import all_instructions
    from gymnast.envs.tasks import resolve_tasks

    for task in resolve_tasks(task_set):
        print(task)
        for sentence in all_instructions(task, split):
            print(f"    {sentence}")


def doctor() -> None:
    """Check that this machine can render the simulator headlessly, and say what to install if not."""
    from gymnast.utils.device import bf16_status
    from gymnast.utils.disk_cache import CACHE_ENV, cache_root
    from gymnast.utils.system import check_rendering

    ok, message = check_rendering()
    print(message)
    print(bf16_status())
    root = cache_root()
    print(f"cache: {root if root else f'off ({CACHE_ENV})'} (sentence embeddings shared by every process)")
    if not ok:
        raise SystemExit(1)


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
    steps: int | None = None,
    tasks: str | None = None,
    keyframes: str | None = None,
    horizon: int | None = None,
    eval_horizon: int | None = None,
    practice_from_rollouts: bool | None = None,
    state_steps: int | None = None,
    wm_steps: int | None = None,
    workers: int | None = None,
    runner: str | None = None,
    real_rl: bool | None = None,
) -> None:
    """World-Gymnast's loop: RL in imagination, a few counted real rollouts of the new policy, the
    world model and the reward model (judge or state model) fine-tuned on them, a real evaluation;
    repeated. Writes OUT/round_k/, OUT/summary.json, OUT/dyna.md (table) and OUT/dyna.png (real
    success against real interactions), beside RL in the real world with the same settings.
    Rerunning skips what finished.

    Args:
        out: run directory.
        policy: the SFT (or RL) run to start from (required unless --resume).
        wm: the world-model run imagined RL starts in; fine-tuned every round.
        judge: the judge run that rewards imagined RL; fine-tuned every round (this or --state).
        state: instead of a judge, a state-model run or ensemble (`gymnast train-state`,
            `gymnast make-ensemble`) whose reward head rewards imagined RL; every member fine-tuned
            every round.
        data: dataset whose scenes imagined RL starts from (default: the one the policy was trained on).
        preset: debug (seconds; tests), demo (minutes) or full.
        resume: continue the run in OUT with the settings and inputs saved there.
        rounds: rounds of the loop (default: the preset's).
        rollouts_per_task: real episodes recorded per task and round (default: the preset's).
        steps: RL steps in imagination per round (default: the preset's).
        tasks: tasks trained and evaluated on (default: the preset's).
        keyframes: where in the start episodes practice begins (see `gymnast rl --help`; default: the preset's).
        horizon: actions per imagined rollout, e.g. 20 for short segments (default: the preset's).
        eval_horizon: actions per real episode, recorded or evaluated (0: --horizon; with segments,
            the task's 150).
        practice_from_rollouts: rounds after the first practise from the previous round's real
            rollouts instead of --data (default: the preset's, off).
        state_steps: fine-tuning steps of the state model per round (default: the preset's).
        wm_steps: fine-tuning steps of the world model per round; 0 keeps the given one (default: the preset's).
        workers: simulator processes (default: the preset's).
        runner: where they run: local, ray or ray:ADDRESS (default: the preset's, local).
        real_rl: also run RL in the real world for comparison (default: the preset's, on).
    """
    from gymnast.experiment.dyna import DYNA_PRESETS, DynaInputs, run_dyna, saved_dyna_settings
    from gymnast.experiment.dyna_report import dyna_table

    def saved():
        config, inputs = saved_dyna_settings(out)
        return config, dataclasses.asdict(inputs)

    config, inputs = resolve(
        "dyna", out, resume, DYNA_PRESETS[preset],
        inputs={"policy": policy, "wm": wm, "judge": judge, "state": state, "data": data},
        overrides={"rounds": rounds, "rollouts_per_task": rollouts_per_task, "rl.steps": steps, "rl.tasks": tasks,
                   "rl.keyframes": keyframes, "rl.horizon": horizon, "rl.eval_horizon": eval_horizon,
                   "practice_from_rollouts": practice_from_rollouts,
                   "state_steps": state_steps, "wm_steps": wm_steps, "workers": workers, "runner": runner,
                   "real_rl": real_rl}, saved=saved, required=("policy", "wm"))
    summary = run_dyna(config, DynaInputs(**inputs), out)
    print(dyna_table(summary))
    print(f"summary: {out / 'summary.json'}, plot: {out / summary['plot']}")


COMMANDS = {
    "collect": collect,
    "inspect": inspect,
    "sft": sft,
    "eval": evaluate_command,
    "train-wm": train_wm,
    "train-state": train_state,
    "eval-wm": eval_wm,
    "make-ensemble": make_ensemble,
    "object-fidelity": object_fidelity,
    "train-judge": train_judge,
    "serve-judge": serve_judge,
    "eval-judge": eval_judge,
    "rl": rl,
    "experiment": experiment,
    "dyna": dyna,
    "imagination": imagination,
    "rl-signal": rl_signal,
    "practice-summary": practice_summary,
    "worldgym": worldgym,
    "contact-sheet": contact_sheet,
    "gap-report": gap_report,
    "tasks": tasks,
    "doctor": doctor,
}


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `gymnast` console script."""
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("OpenGL").setLevel(logging.WARNING)
    try:
        tyro.extras.subcommand_cli_from_dict(COMMANDS, args=sys.argv[1:] if argv is None else argv,
                                             prog="gymnast", description=__doc__)
    except (ValueError, FileNotFoundError) as error:
        # Bad input is the user's to fix: say what is wrong without a traceback.
        print(f"gymnast: error: {error}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
