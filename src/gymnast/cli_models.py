"""`gymnast` subcommands that train and measure learned parts: the world model, the judge and RL.

Each is a thin call into the library; `gymnast.cli` gathers them with the others.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated, Literal

import tyro


def train_wm(
    data: Path,
    out: Path,
    preset: Literal["debug", "demo", "full"] = "full",
    resume: bool = False,
    steps: int | None = None,
    seed: int | None = None,
) -> None:
    """Train the embedded world model on every episode of a dataset (held-out scenes excepted).

    Args:
        data: dataset directory (from `gymnast collect`).
        out: run directory: checkpoints, metrics.jsonl, config.json, videos/.
        preset: debug (seconds), demo (minutes) or full (the default world model, under an hour on 2 cores).
        resume: continue the run in OUT from its last checkpoint, with the settings saved there.
        steps: override the preset's optimizer steps.
        seed: override the seed.
    """
    from gymnast.world_model.train import WM_PRESETS, saved_train_config, train_world_model

    if resume:
        config = saved_train_config(out)
    else:
        overrides = {"steps": steps, "seed": seed}
        config = dataclasses.replace(WM_PRESETS[preset], **{k: v for k, v in overrides.items() if v is not None})
    checkpoint = train_world_model(data, out, config, resume=resume)
    print(f"world model: {checkpoint}")


def eval_wm(
    wm: Path,
    data: Path,
    out: Path,
    max_episodes: int = 0,
    videos: int = 6,
    gifs: int = 0,
    control_scenes: int = 10,
    reanchor_every: int | None = None,
) -> None:
    """Measure a world model's open-loop fidelity and controllability on held-out episodes.

    Args:
        wm: world-model run (or checkpoint) directory.
        data: dataset directory; its episodes from held-out scenes are used.
        out: report JSON; side-by-side videos go to <out stem>_videos/.
        max_episodes: evaluate at most this many held-out episodes (0 = all).
        videos: side-by-side videos (real | imagined | difference) to write.
        gifs: also write the first GIFS of them as small looping GIFs.
        control_scenes: held-out scenes for the controllability check (0 skips it).
        reanchor_every: override how often a long rollout re-encodes its own frames (0 = never).
    """
    from gymnast.world_model.controllability import ControllabilityConfig
    from gymnast.world_model.evaluate import WorldModelEvalConfig, evaluate_world_model, format_report

    config = WorldModelEvalConfig(max_episodes=max_episodes, videos=videos, gifs=gifs,
                                  controllability=ControllabilityConfig(scenes=control_scenes), reanchor_every=reanchor_every)
    report = evaluate_world_model(wm, data, out, config)
    print(format_report(report))
    print(f"report: {out}")


def train_judge(
    data: Path,
    out: Path,
    wm: Path | None = None,
    preset: Literal["debug", "demo", "full"] = "full",
    resume: bool = False,
    steps: int | None = None,
) -> None:
    """Train the embedded success judge on real episodes (and their re-imaginings with --wm), then
    report its TPR and FPR on held-out real and imagined videos.

    Args:
        data: dataset directory (from `gymnast collect`).
        out: run directory: checkpoints, metrics.jsonl, metrics.json (the held-out figures).
        wm: world-model run: also train and measure on its re-imagining of every episode.
        preset: debug (seconds), demo (minutes) or full.
        resume: continue the run in OUT from its last checkpoint, with the settings saved there.
        steps: override the preset's optimizer steps.
    """
    from gymnast.reward.train_judge import JUDGE_PRESETS, saved_judge_config
    from gymnast.reward.train_judge import train_judge as train

    config = saved_judge_config(out) if resume else JUDGE_PRESETS[preset]
    if steps is not None and not resume:
        config = dataclasses.replace(config, steps=steps)
    report = train(data, out, config, wm=wm, resume=resume)
    print(json.dumps({k: v for k, v in report.items() if k.startswith(("real", "imagined"))}, indent=2))
    print(f"judge: {out}")


def serve_judge(judge: Path, port: int = 8000, host: str = "127.0.0.1") -> None:
    """Serve the learned judge over the OpenAI chat-completions protocol (POST /v1/chat/completions).

    Args:
        judge: judge run (or checkpoint) directory, from `gymnast train-judge`.
        port: TCP port to listen on.
        host: address to bind (127.0.0.1: this machine only).
    """
    import time

    from gymnast.reward.serve import judge_server

    with judge_server(judge, host, port) as server:
        print(f"judge: {judge} at {server.url} (model gymnast-judge); Ctrl-C stops", flush=True)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass


def eval_judge(
    reward: str,
    data: Path,
    out: Path,
    wm: Path | None = None,
    heldout_fraction: float = 0.1,
) -> None:
    """Measure a 0/1 judge (judge:RUN or vlm:MODEL@BASE_URL) on held-out episodes: TPR and FPR on
    real videos and, with --wm, on the world model's re-imagining of the same episodes.

    Args:
        reward: the judge, e.g. judge:runs/judge or vlm:gpt-4o@https://api.openai.com/v1 (key from OPENAI_API_KEY).
        data: dataset directory; the episodes of its held-out scenes are judged.
        out: report JSON.
        wm: world-model run whose imagined videos are judged too.
        heldout_fraction: the held-out share of scenes (the world model's, so its videos are unseen).
    """
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.reward.select import make_reward
    from gymnast.reward.train_judge import evaluate_judge, heldout_videos
    from gymnast.utils.atomic import write_json

    if not reward.startswith(("judge:", "vlm:")):
        raise ValueError(f"eval-judge measures judges (judge:RUN or vlm:MODEL@BASE_URL), got {reward!r}")
    report = evaluate_judge(make_reward(reward), heldout_videos(EpisodeDataset(data), heldout_fraction, wm))
    report |= {"reward": reward, "data": str(data), "wm": str(wm) if wm else None}
    write_json(out, report)
    print(json.dumps(report, indent=2))


def rl(
    out: Path,
    policy: Path | None = None,
    env: Literal["imagined", "sim", "real"] | None = None,
    reward: str | None = None,
    wm: Path | None = None,
    data: Path | None = None,
    preset: Literal["debug", "demo", "full"] = "full",
    resume: bool = False,
    steps: int | None = None,
    tasks: str | None = None,
    fresh_scenes: bool = False,
    gap: str | None = None,
    lr: float | None = None,
    temperature: float | None = None,
    group_size: int | None = None,
    starts_per_step: int | None = None,
    eval_every: int | None = None,
    eval_episodes: int | None = None,
    workers: int | None = None,
    seed: int | None = None,
) -> None:
    """Fine-tune a policy with GRPO in the world model (imagined), the software simulator or the real world.

    Args:
        out: run directory: checkpoints, metrics.jsonl, tensorboard/, videos/, summary.json.
        policy: the SFT (or RL) run or checkpoint to start from (required unless --resume).
        env: where rollouts happen: imagined (in --wm), sim (the software simulator, --gap) or real.
        reward: judge:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense.
        wm: the world model run (needed by --env imagined and --reward verified).
        data: dataset whose scenes are the start states (default: the one the policy was trained on).
        preset: debug (seconds), demo (minutes) or full.
        resume: continue the run in OUT from its last checkpoint, with the settings saved there.
        steps: override the number of RL steps.
        tasks: override the training tasks (comma-separated names or sets).
        fresh_scenes: sim/real only: start each group from a new scene instead of the dataset's (no dataset needed).
        gap: override the software simulator's gap (mild, strong).
        lr: override the learning rate.
        temperature: override the rollout temperature.
        group_size: override the rollouts per start state.
        starts_per_step: override the start states per step.
        eval_every: override the steps between evaluations.
        eval_episodes: override the evaluation episodes per task.
        workers: override the simulator processes.
        seed: override the seed.
    """
    from gymnast.rl.train import RL_PRESETS, RLRun, saved_rl_settings, train_rl

    if resume:
        run_spec, config = saved_rl_settings(out)
    elif policy is None or env is None or reward is None:
        raise ValueError("gymnast rl needs --policy, --env and --reward (or --resume to continue OUT)")
    else:
        run_spec = RLRun(str(policy), env, reward, str(wm) if wm else None, str(data) if data else None)
        overrides = {"steps": steps, "tasks": tasks, "gap": gap, "lr": lr, "temperature": temperature,
                     "group_size": group_size, "starts_per_step": starts_per_step, "eval_every": eval_every,
                     "eval_episodes": eval_episodes, "workers": workers, "seed": seed}
        config = dataclasses.replace(RL_PRESETS[preset], **{k: v for k, v in overrides.items() if v is not None})
        config = dataclasses.replace(config, fresh_scenes=fresh_scenes or config.fresh_scenes)
    summary = train_rl(run_spec, out, config, resume=resume)
    summary.pop("curve")
    print(json.dumps(summary, indent=2))


def experiment(
    out: Path,
    preset: Literal["debug", "demo", "full"] = "full",
    reuse: Annotated[list[str], tyro.conf.UseAppendAction] = [],  # noqa: B006 (read by tyro, never mutated)
    workers: int | None = None,
) -> None:
    """The headline comparison: data, SFT, world model, judge, six arms, real-world evaluation and
    the WorldGym check, then OUT/report.md, OUT/summary.json and OUT/plots/. Rerunning the same
    command skips the stages that finished and continues an interrupted one.

    Args:
        out: experiment directory.
        preset: debug (a minute; tests), demo (a few tasks, what `make demo` runs) or full (MT10).
        reuse: a stage to take from an earlier run instead of running it, as STAGE=DIR (collect=DATASET,
            sft=RUN, world_model=RUN, judge=RUN); repeat for several, e.g. --reuse collect=data/mt10
            --reuse world_model=runs/wm_full.
        workers: simulator processes (default: the preset's, one per core on 2 cores).
    """
    from gymnast.experiment.config import EXPERIMENT_PRESETS
    from gymnast.experiment.pipeline import run_experiment
    from gymnast.experiment.report import format_table
    from gymnast.experiment.stages import parse_reuse

    config = EXPERIMENT_PRESETS[preset]
    if workers is not None:
        config = dataclasses.replace(config, workers=workers)
    summary = run_experiment(config, out, parse_reuse(reuse))
    print(format_table(summary))
    print(f"report: {out / 'report.md'}")
