"""`gymnast` commands that measure how far imagination can be trusted before practice is spent on it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

from gymnast.config import CommaFloats
from gymnast.experiment.worldgym import DEFAULT_NOISE
from gymnast.reward.spec import RewardSpec


def imagination(
    policy: Path,
    wm: Path,
    reward: str,
    out: Path,
    tasks: str = "mt10",
    episodes: int = 10,
    horizon: int = 150,
    batch: int = 32,
    workers: int = 1,
    runner: str = "local",
    videos: int = 4,
    seed: int = 0,
    robot_state: Path | None = None,
) -> None:
    """Measure imagination under a policy: its greedy rollouts in the world model, judged, against
    the same actions replayed in the real world (agreement, false successes, PSNR per step) and
    against the policy run in the real world; writes OUT/imagination.json, imagination.md,
    psnr.png and side-by-side videos.

    Args:
        policy: SFT/RL run (or checkpoint) directory; also lerobot:PATH (a LeRobot pretrained_model folder),
            or your own: python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-policy --help).
        wm: world-model run (or checkpoint) directory, or an ensemble; or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help).
        reward: a 0/1 judge: judge:RUN or vlm:MODEL@BASE_URL (key from OPENAI_API_KEY).
        out: report directory.
        tasks: task names and/or sets, comma-separated.
        episodes: evaluation scenes per task.
        horizon: actions per rollout.
        batch: rollouts stepped together.
        workers: simulator processes for the real-world envs.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        videos: side-by-side videos (imagined | real replay | difference), disagreements first.
        seed: reset seed of the envs (what a stochastic world model draws from).
        robot_state: for a policy that reads the robot's state (observation.state), a state model
            (or ensemble) run that imagines it beside the world model (gymnast train-state).
    """
    from gymnast.experiment.imagination import ImaginationConfig, measure_imagination_runs
    from gymnast.experiment.imagination_report import format_imagination

    config = ImaginationConfig(tasks=tasks, episodes=episodes, horizon=horizon, batch=batch, workers=workers,
                               runner=runner, videos=videos, seed=seed)
    report = measure_imagination_runs(policy, wm, RewardSpec.parse(reward), config, out, robot_state=robot_state)
    print(format_imagination(report))
    print(f"report: {out / 'imagination.md'}")


def rl_signal(
    out: Path,
    policy: Path | None = None,
    wm: Path | None = None,
    reward: str | None = None,
    like: Path | None = None,
    tasks: str | None = None,
    starts_per_task: int = 8,
    task_starts: dict[str, int] | None = None,
    group_size: int | None = None,
    temperature: float | None = None,
    horizons: tuple[int, ...] | None = None,
    batch: int | None = None,
    workers: int = 2,
    runner: str = "local",
    seed: int | None = None,
    data: Path | None = None,
    keyframes: Literal["first", "uniform", "near_success", "failures"] | None = None,
    heldout_fraction: float = 0.1,
    robot_state: Path | None = None,
) -> None:
    """Measure whether RL in imagination would push the policy where the real world would: GRPO
    groups sampled in the world model and judged, their actions replayed in the real world from the
    same starts, and the correlation of the imagined advantages with the real ones (real success,
    and the real dense return) by horizon; writes OUT/signal.json and OUT/signal.md.

    Args:
        out: report directory.
        policy: SFT/RL run (or checkpoint) directory (default: --like's); also lerobot:PATH (a LeRobot
            pretrained_model folder), or your own: python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast
            check-policy --help).
        wm: world-model run (or checkpoint) directory, or an ensemble (default: --like's); or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help).
        reward: a reward of the video alone: judge:RUN or vlm:MODEL@BASE_URL (key from OPENAI_API_KEY);
            or a grounded world model's reward head, state:RUN (from `gymnast train-state`) (default: --like's).
        like: an RL run in imagination whose practice is measured: its policy, world model, reward,
            tasks, starts (its dataset's keyframes), horizon, group size, temperature and seed, each
            unless given here.
        tasks: task names and/or sets, comma-separated (default: --like's, else the four weak tasks).
        starts_per_task: starts (GRPO groups) per task.
        task_starts: tasks that take another number of starts, as TASK N pairs, e.g. `--task-starts
            push-v3 12 reach-v3 12` (the experiment's weak tasks take `signal_weak_scenes`).
        group_size: rollouts per scene (default: --like's, else 8).
        temperature: the policy's sampling temperature (default: --like's, else 1).
        horizons: horizons read out, the largest the rollouts' length (default: --like's horizon, else 50 100 150).
        batch: rollouts stepped together, a multiple of the group size (default: 64 or the nearest multiple).
        workers: simulator processes for the real-world replays.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        seed: seed of the scenes and of the policy's samples (default: --like's, else 0).
        data: start from keyframes of this dataset's held-out episodes (segments as short as
            --horizons), restored in the real world by replaying the actions that led there;
            without it (and without --like), from fresh scenes' first frames.
        keyframes: how keyframes are drawn: first, uniform, near_success (the frames before the first
            success) or failures (episodes that failed) (default: --like's, else uniform).
        heldout_fraction: the share of --data's scenes the models held out, where keyframes come from;
            0 for a dataset they never trained on (e.g. the policy's own rollouts on new seeds).
        robot_state: for a policy that reads the robot's state (observation.state), a state model
            (or ensemble) run that imagines it beside the world model (default: --like's).
    """
    from gymnast.experiment.practice_signal import SignalConfig, batch_for, measure_signal_runs, practice_of

    inputs, settings = practice_of(like) if like is not None else ({}, {})
    given = {"policy": policy, "wm": wm, "reward": reward}
    inputs |= {name: str(value) for name, value in (given | {"robot_state": robot_state}).items() if value is not None}
    missing = [f"--{name}" for name in given if name not in inputs]
    if missing:
        raise ValueError(f"rl-signal needs {', '.join(missing)} (or --like RUN, an RL run in imagination)")
    chosen = {"tasks": tasks, "group_size": group_size, "temperature": temperature, "seed": seed,
              "horizons": None if horizons is None else tuple(horizons), "batch": batch,
              "data": None if data is None else str(data), "keyframes": keyframes}
    settings |= {name: value for name, value in chosen.items() if value is not None}
    if batch is None and "group_size" in settings:
        settings["batch"] = batch_for(settings["group_size"])
    config = SignalConfig(**settings, starts_per_task=starts_per_task, task_starts=task_starts or {}, workers=workers,
                          runner=runner, heldout_fraction=heldout_fraction)
    measure_signal_runs(inputs["policy"], inputs["wm"], RewardSpec.parse(inputs["reward"]), config, out,
                        robot_state=inputs.get("robot_state"))
    print((out / "signal.md").read_text())


def practice_summary(
    out: Path,
    run: tuple[str, ...],
) -> None:
    """Gather RL runs into a practice summary (results/practice/summary.json): per task set, SFT (the
    first run's step-0 evaluation) and each RL arm's last real-world evaluation.

    Args:
        out: the JSON to write.
        run: TASKSET:ARM=RUN, one per run; ARM is imagined_rl or real_rl (e.g. weak:imagined_rl=runs/practice_weak).
    """
    from gymnast.experiment.practice_summary import practice_summary as summarize

    runs: dict[str, dict[str, Path]] = {}
    for item in run:
        named, _, path = item.partition("=")
        task_set, _, arm = named.partition(":")
        if not (task_set and arm and path):
            raise ValueError(f"--run {item!r}: expected TASKSET:ARM=RUN, e.g. weak:imagined_rl=runs/practice_weak")
        runs.setdefault(task_set, {})[arm] = Path(path)
    print(json.dumps(summarize(runs, out), indent=2))


def worldgym(
    policy: Path,
    wm: Path,
    judge: Path,
    out: Path,
    noise: CommaFloats = DEFAULT_NOISE,
    tasks: str = "mt10",
    episodes: int = 10,
    horizon: int = 150,
    workers: int = 2,
    runner: str = "local",
    seed: int = 0,
) -> None:
    """WorldGym over a noise ladder: can the world model and judge rank policies like the real world?

    Each noise level of POLICY is rolled out greedily in imagination (judged) and in the real world
    from the same evaluation seeds; writes OUT/worldgym.json (rows with 95% intervals, Pearson and
    Spearman, settings, seconds) and OUT/worldgym.png, and prints the table.

    Args:
        policy: the SFT/RL run (or checkpoint) the ladder is made of; also lerobot:PATH (a LeRobot
            pretrained_model folder), or your own: python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast
            check-policy --help).
        wm: world-model run the policies are imagined in; or your own: python:MODULE:FACTORY[@ARG] or
            plugin:NAME[@ARG] (gymnast check-wm --help).
        judge: learned-judge run that scores the imagined rollouts.
        out: output directory.
        noise: action-noise std per level (actions span [-1, 1]); 0 is the policy itself, inf random actions.
        tasks: task names or sets, comma-separated.
        episodes: evaluation seeds per task, in each world.
        horizon: actions per episode, in each world.
        workers: simulator processes for the real-world rollouts.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        seed: seed of the noise.
    """
    from gymnast.experiment.worldgym import format_rows, run_worldgym

    result = run_worldgym(policy, noise, wm, judge, tasks, episodes, out, horizon=horizon, workers=workers, seed=seed,
                          runner=runner)
    print(format_rows(result))
    print(f"report: {out / 'worldgym.json'}, plot: {out / 'worldgym.png'}")
