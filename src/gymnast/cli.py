"""The `gymnast` command: one subcommand per job, each a thin call into the library."""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
from pathlib import Path
from typing import Annotated, Literal

import tyro

import gymnast  # noqa: F401  (sets MUJOCO_GL before anything imports mujoco)
from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig
from gymnast.cli_models import (eval_judge, eval_wm, experiment, imagination, make_ensemble, object_fidelity, rl, serve_judge,
                                train_judge, train_wm, worldgym)
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
        policy: an SFT/RL run directory (its newest checkpoint), or 'expert' for the scripted reference.
        out: JSON report (per-episode records included); videos are saved beside it in <name>_videos/.
        config: tasks, episodes, perturbation, gap and workers.
    """
    from gymnast.eval.evaluate import evaluate, format_summary

    report = evaluate(policy, config, out)
    print(format_summary(report))
    print(f"report: {out}")


def sft(
    data: Path,
    out: Path,
    preset: Literal["debug", "demo", "full"] = "full",
    resume: bool = False,
    demos_per_task: int | None = None,
    steps: int | None = None,
    vision: Literal["cnn", "efficientnet"] | None = None,
    tasks: str | None = None,
    seed: int | None = None,
) -> None:
    """Behaviour-clone the embedded VLA on N successful expert demonstrations per task.

    Args:
        data: dataset directory (from `gymnast collect`).
        out: run directory: checkpoints, metrics.jsonl, config.json.
        preset: debug (seconds), demo (minutes) or full (the default policy).
        resume: continue the run in OUT from its last checkpoint, with the settings saved there.
        demos_per_task: override the preset's demonstrations per task.
        steps: override the preset's optimizer steps.
        vision: override the image encoder.
        tasks: restrict to these tasks (comma-separated).
        seed: override the seed.
    """
    from gymnast.policy.sft import SFT_PRESETS, saved_sft_config, train_sft

    if resume:
        config = saved_sft_config(out)
    else:
        overrides = {"demos_per_task": demos_per_task, "steps": steps, "tasks": tasks, "seed": seed}
        config = dataclasses.replace(SFT_PRESETS[preset], **{k: v for k, v in overrides.items() if v is not None})
        if vision is not None:
            config = dataclasses.replace(config, vla=dataclasses.replace(config.vla, vision=vision))
    checkpoint = train_sft(data, out, config, resume=resume)
    print(f"policy: {checkpoint}")


def inspect(data: Path, sheet: Path | None = None, episodes: int = 10) -> None:
    """Summarise a dataset (v3.0 or v2.1): episodes, success by task and behaviour, codec error.

    Args:
        data: dataset directory.
        sheet: also write a PNG contact sheet (first, middle and last frame of a few episodes).
        episodes: how many episodes the contact sheet shows.
    """
    from gymnast.data.collect import success_table
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.utils.images import contact_sheet, save_png

    dataset = EpisodeDataset(data)
    infos = dataset.episodes
    print(f"{data}: LeRobot {dataset.info['codebase_version']}, {len(infos)} episodes, "
          f"{sum(dataset.lengths)} steps, {dataset.fps} fps, images {dataset.image_shape}")
    recorded = dataset.info.get("gymnast", {})
    if "video_psnr_db" in recorded:
        print(f"video: {json.dumps(recorded['codec'])}, decoded-vs-raw PSNR "
              f"min {recorded['video_psnr_db']['min']:.1f} dB, mean {recorded['video_psnr_db']['mean']:.1f} dB")
    print(format_success_table(success_table(infos)))
    if sheet is not None:
        frames, labels = [], []
        for i in range(min(episodes, len(infos))):
            episode = dataset.load(i)
            for t in (0, episode.length // 2, episode.length):
                frames.append(episode.frames[t])
                labels.append(f"{i} {infos[i].task[:14]} t={t}")
        save_png(contact_sheet(frames, labels, columns=6), sheet)
        print(f"contact sheet: {sheet}")


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
    from gymnast.envs.metaworld import MetaWorldEnv
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.envs.visibility import object_pixel_counts
    from gymnast.utils.atomic import write_json
    from gymnast.utils.images import contact_sheet as tile
    from gymnast.utils.images import save_png

    frames, labels, sizes = [], [], {}
    for task in resolve_tasks(tasks):
        world = MetaWorldEnv(task, env, gap=gap)
        obs, _ = world.reset(seed=seed)
        frames.append(obs["image"])
        labels.append(task.removesuffix("-v3"))
        sizes[task] = object_pixel_counts(world)
        world.close()
    save_png(tile(frames, labels, columns=5, scale=max(1, 192 // env.image_size)), out)
    write_json(out.with_suffix(".json"), {"image_size": env.image_size, "seed": seed, "pixels": sizes})
    print(f"contact sheet: {out}")


def gap_report(
    out: Path = Path("docs/sim_gap.json"),
    tasks: str = "mt10",
    episodes: int = 10,
    levels: tuple[str, ...] = ("mild", "strong"),
    workers: int = 2,
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
        first_seed: first data seed.
        env: camera, image size and horizon.
    """
    from tqdm import tqdm

    from gymnast.envs.gap import get_gap
    from gymnast.envs.gap_report import measure_gap, summarise, to_markdown
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.utils.atomic import write_bytes, write_json

    task_list = resolve_tasks(tasks)
    report = {"tasks": list(task_list), "episodes_per_task": episodes, "horizon": env.horizon, "levels": {}}
    for level in levels:
        records = list(tqdm(measure_gap(level, task_list, episodes, env, workers, first_seed),
                            total=len(task_list) * episodes, desc=f"gap {level}", unit="ep"))
        summary = summarise(records)
        report["levels"][level] = {"gap": dataclasses.asdict(get_gap(level)), **summary, "records": records}
        overall = summary["overall"]
        print(f"{level:>7}: expert success real {overall['real_expert_success']:.0%} -> sim "
              f"{overall['sim_expert_success']:.0%}; replayed real actions succeed "
              f"{overall['replay_success']:.0%}, hand drift {overall['hand_divergence_cm_final']:.1f} cm, "
              f"object drift {overall['object_divergence_cm_final']:.1f} cm")
    write_json(out, report)
    write_bytes(out.with_suffix(".md"), to_markdown(report).encode())
    print(f"report: {out} and {out.with_suffix('.md')}")


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
    from gymnast.utils.system import check_rendering

    ok, message = check_rendering()
    print(message)
    if not ok:
        raise SystemExit(1)


def format_success_table(table: dict) -> str:
    """Success by task (rows) and behaviour (columns) as aligned text: 'successes/episodes'."""
    behaviours = sorted({b for row in table.values() for b in row})
    width = max([len(t) for t in table] + [4])
    lines = [f"{'task':<{width}}  " + "  ".join(f"{b:>17}" for b in behaviours)]
    for task, row in sorted(table.items()):
        cells = [f"{row[b][0]:>3}/{row[b][1]:<3} ({row[b][0] / row[b][1]:>4.0%})" if b in row else f"{'-':>17}"
                 for b in behaviours]
        lines.append(f"{task:<{width}}  " + "  ".join(f"{c:>17}" for c in cells))
    return "\n".join(lines)



COMMANDS = {
    "collect": collect,
    "inspect": inspect,
    "sft": sft,
    "eval": evaluate_command,
    "train-wm": train_wm,
    "eval-wm": eval_wm,
    "make-ensemble": make_ensemble,
    "object-fidelity": object_fidelity,
    "train-judge": train_judge,
    "serve-judge": serve_judge,
    "eval-judge": eval_judge,
    "rl": rl,
    "experiment": experiment,
    "imagination": imagination,
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
