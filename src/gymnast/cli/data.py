"""`gymnast` commands on recorded data and the real world itself: record, inspect, picture, gap report, tasks."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import tyro

from gymnast.cli.flags import KeyFlags, feature_keys
from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig
from gymnast.data.summary import format_success_table


def collect(
    out: Path,
    config: Annotated[CollectConfig, tyro.conf.arg(name="")] = CollectConfig(),
    policy: Path | None = None,
    temperature: float = 0.0,
    imagine_with: Path | None = None,
    replay: Path | None = None,
) -> None:
    """Record scripted episodes (experts, noisy experts, failures), or a learned policy's own
    rollouts, into a LeRobot v3.0 dataset; or replay a recorded dataset's episodes in other
    cameras or at another image size.

    Rerunning the same command resumes: episodes already in OUT are skipped.

    Args:
        out: dataset directory (created if missing).
        config: what to record.
        policy: an SFT/RL run directory: record its rollouts (behaviour policy-<tag>, greedy plus the
            --noise levels, no failure episodes) instead of the scripted behaviours; also lerobot:PATH (a
            LeRobot pretrained_model folder), or your own: python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG]
            (gymnast check-policy --help).
        temperature: with --policy, sample the action tokens at this temperature (0: greedy).
        imagine_with: with --policy, a world-model run (or your own: python:MODULE:FACTORY[@ARG] or
            plugin:NAME[@ARG]): the policy plans each episode closed loop in it from the scene's first
            frame and the real world executes the plan, so that every episode labels an imagined rollout
            with its real outcome (judge data for `gymnast train-judge --wm` on the same world model).
        replay: a dataset gymnast recorded: execute each of its episodes' actions again from the
            same scene and record what --cameras and --env.image-size show (the same episodes,
            checked step by step; its tasks, seeds, horizon and end at success are kept).
    """
    if replay is not None:
        if policy is not None or temperature or imagine_with:
            raise ValueError("--replay records the episodes of a dataset again; it takes no --policy, "
                             "--temperature or --imagine-with")
        from gymnast.data.replay import replay_dataset

        table = replay_dataset(replay, out, config)
    elif policy is not None:
        from gymnast.eval.record import record_policy

        table = record_policy(policy, config, out, temperature=temperature, imagine_with=imagine_with)
    elif temperature or imagine_with:
        raise ValueError("--temperature and --imagine-with apply to a learned policy; give --policy RUN too")
    else:
        from gymnast.data.collect import collect as run_collect

        table = run_collect(config, out)
    print(format_success_table(table))
    print(f"dataset: {out}")


def inspect(
    data: Path,
    sheet: Path | None = None,
    episodes: int = 10,
    camera: str | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
    check: bool = False,
) -> None:
    """Summarise a dataset (v3.0, v2.1 or v2.0): episodes, the features read, success by task and behaviour,
    codec error, and what reading it assumed where it departs from the LeRobot specification. A dataset
    whose features are named otherwise gets the candidates for the actions, the states and the cameras
    instead, and the flags that read them.

    Args:
        data: dataset directory.
        check: instead, read the whole dataset as training would and list every deviation from the LeRobot
            specification with the decision it leads to; exits with status 1 where training cannot proceed.
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

    if check:
        from gymnast.data.check import check_dataset, format_check

        report = check_dataset(data, camera, feature_keys(keys))
        print(format_check(data, report))
        if report.blocking:
            raise SystemExit(1)
        return
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


def stills(
    videos: tuple[Path, ...],
    out: Path,
    frames: str = "0,20,40,80,150",
    tiles: str = "0",
    tile_width: int = 0,
) -> None:
    """Still frames of videos in one PNG: a row per video (or per tile of a video that holds several
    rollouts side by side, as `gymnast rl`'s group videos do), a column per frame index; to compare
    what rollouts looked like at the same moments, e.g. a ladder rung's imagined rollouts beside
    real ones.

    Args:
        videos: mp4 files, one row (or one row per tile) each, in order.
        out: PNG to write.
        frames: frame indices, comma-separated (frame t of an RL rollout video follows t actions; a
            frame past a video's end shows its last).
        tiles: which tiles of each video, comma-separated, counted from 0 at the left.
        tile_width: width of one tile in pixels (an RL group video: 2 x 96 x cameras for 96-px
            frames); 0: each video is one tile.
    """
    from gymnast.utils.images import save_png
    from gymnast.utils.stills import video_stills

    sheet = video_stills(videos, parse_indices(frames, "--frames"), parse_indices(tiles, "--tiles"), tile_width)
    print(f"stills: {save_png(sheet, out)}")


def parse_indices(text: str, flag: str) -> list[int]:
    """'0,20,40' as [0, 20, 40]; a ValueError naming `flag` for anything else."""
    try:
        return [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise ValueError(f"{flag} takes comma-separated integers, got {text!r}") from None
