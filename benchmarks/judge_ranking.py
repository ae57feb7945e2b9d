"""Can a learned judge rank the policy's own real rollouts, with one camera or several?

For `--scenes` new scenes of each task, `--group` rollouts of the policy sampled at `--temperature`
are played in the real world for the whole horizon, on past a success as `gymnast rl-signal`'s real
replays and imagined rollouts go (or, with `--stop-at-success`, ending at it as RL's real episodes
do), with every camera the judges need rendered (the policy sees its own cameras,
`gymnast.eval.actors.PolicyActor.seen`), at the policy's image size; a judge of another size sees
the same rollouts replayed at its own (the same actions from the same scene: the same states,
rewards and successes, checked).
Each judge scores the real videos through its own cameras, and its GRPO advantages within each
group are held against those of the real success and of the real dense return
(`gymnast.experiment.signal_report.signal_figures`, as `gymnast rl-signal` reports its
`real_video` readout): no world model is involved, so this is the judge's own ranking.

    .venv/bin/python benchmarks/judge_ranking.py --judge front=RUN --judge both=RUN \
        [--policy results/sft/policy] [--tasks ...] [--scenes 6] [--group 8] [--stop-at-success] [--out JSON] [--resume]

Prints and writes --out (default benchmarks/results/judge_ranking.json).
"""

from __future__ import annotations

import argparse
import functools
import json
import time
import zlib
from pathlib import Path

import numpy as np
import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.config import EnvConfig
from gymnast.envs.engine import ReplayActor, play_episode
from gymnast.envs.parallel import cached_env, parallel_map
from gymnast.envs.tasks import DATA_SEEDS
from gymnast.eval.actors import PolicyActor, load_run_policy
from gymnast.experiment.practice_signal import dense_return
from gymnast.experiment.signal_report import signal_figures
from gymnast.reward.judges.train import load_judge
from gymnast.utils.atomic import write_bytes, write_json

RESULTS = Path(__file__).parent / "results" / "judge_ranking.json"
WEAK_TASKS = "reach-v3,push-v3,pick-place-v3,peg-insert-side-v3"


@functools.lru_cache(maxsize=None)
def _judge(run: str):
    return load_judge(Path(run)).eval()


def play_and_judge(job: tuple) -> dict:
    """One rollout of the policy in the real world, scored by every judge: (task, scene, member,
    policy, judges {name: run}, cameras, temperature, stop at success) -> its record."""
    task, scene, member, policy, judges, cameras, temperature, stop = job
    loaded = load_run_policy(policy)
    size = loaded.config.image_size
    env = cached_env(task, EnvConfig(image_size=size, cameras=cameras, terminate_on_success=stop))
    actor = PolicyActor(loaded, temperature=temperature, seed=zlib.crc32(f"{task}/{scene}/{member}".encode()))
    run = play_episode(env, actor, scene, record=("frames", "rewards", "successes"))
    # (T+1, H, V*W, 3) the env's cameras side by side, at the policy's size and at every other size a judge sees
    frames = {size: torch.from_numpy(np.stack(run.frames))}
    for other in {_judge(path).config.image_size for path in judges.values()} - {size}:
        frames[other] = _replayed_frames(run, task, scene, EnvConfig(image_size=other, cameras=cameras,
                                                                     terminate_on_success=stop))
    scores = {}
    for name, path in judges.items():
        judge = _judge(path)
        seen = _views(frames[judge.config.image_size], cameras, judge.config.cameras)
        with torch.no_grad():
            probability = float(judge.probability(seen[None], [env.instruction])[0])
        scores[name] = {"probability": probability, "verdict": float(probability >= judge.config.threshold)}
    rewards = torch.tensor(run.rewards)[None]
    success_by_step = torch.tensor(run.successes)[None].cummax(1).values
    return {"task": task, "scene": scene, "member": member, "success": bool(run.success),
            "return": float(dense_return(rewards, success_by_step)[0]), "steps": run.steps, "scores": scores}


def _views(frames: torch.Tensor, cameras: tuple[str, ...], wanted: tuple[str, ...]) -> torch.Tensor:
    """(T+1, H, V'*H, 3) the `wanted` cameras side by side, cut from frames of `cameras` side by side."""
    size = frames.shape[1]
    return torch.cat([frames[:, :, cameras.index(c) * size:(cameras.index(c) + 1) * size] for c in wanted], dim=2)


def _replayed_frames(run, task: str, scene: int, config: EnvConfig) -> torch.Tensor:
    """The frames of `run` rendered under `config` (another image size): its actions replayed from the
    same scene, which gives the same states, rewards and successes (checked), seen at that size."""
    replay = play_episode(cached_env(task, config), ReplayActor(np.stack(run.actions)), scene,
                          record=("frames", "rewards", "successes"))
    if replay.rewards != run.rewards or replay.successes != run.successes:
        raise RuntimeError(f"{task} scene {scene}: replaying the rollout at {config.image_size} px did not repeat it")
    return torch.from_numpy(np.stack(replay.frames))


def figures(records: list[dict], group: int, judges: dict[str, str]) -> dict:
    """Every judge's readouts against the real outcomes of whole groups (records in group order)."""
    real = torch.tensor([r["success"] for r in records]).view(-1, group)
    returns = torch.tensor([r["return"] for r in records]).view(-1, group)
    out = {}
    for name in judges:
        for readout, binary in (("verdict", True), ("probability", False)):
            values = torch.tensor([r["scores"][name][readout] for r in records]).view(-1, group)
            out[f"{name}.{readout}"] = signal_figures(values, real, binary, returns)
    out["real_dense"] = signal_figures(returns, real, False, returns)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--judge", action="append", required=True, help="NAME=RUN, once per judge")
    parser.add_argument("--policy", default="results/sft/policy")
    parser.add_argument("--tasks", default=WEAK_TASKS)
    parser.add_argument("--scenes", type=int, default=6, help="new scenes per task")
    parser.add_argument("--group", type=int, default=8, help="rollouts per scene")
    parser.add_argument("--temperature", type=float, default=1.0)
    parser.add_argument("--stop-at-success", action="store_true",
                        help="end each episode at its first success (as RL's real episodes) instead of playing the horizon")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--resume", action="store_true",
                        help="keep the rollouts an interrupted run logged beside --out (.rollouts.jsonl) and play the rest")
    args = parser.parse_args()
    judges = dict(item.split("=", 1) for item in args.judge)
    cameras = tuple(dict.fromkeys(c for path in judges.values() for c in load_judge(Path(path)).config.cameras))
    cameras = tuple(sorted(cameras, key=lambda c: c != "front"))  # the policy's front view first
    tasks = args.tasks.split(",")
    draw = np.random.default_rng(args.seed)
    scenes = {task: [int(s) for s in draw.choice(10_000, size=args.scenes, replace=False) + DATA_SEEDS.start + 500_000]
              for task in tasks}  # far from the data seeds the datasets were recorded on
    jobs = [(task, scene, member, args.policy, judges, cameras, args.temperature, args.stop_at_success)
            for task in tasks for scene in scenes[task] for member in range(args.group)]
    settings = {**{k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k != "resume"},
                "cameras": list(cameras), "judges": judges, "scenes": scenes}
    started = time.perf_counter()
    records = _played(jobs, settings, args.out.with_suffix(".rollouts.jsonl"), args.resume, args.workers)
    records.sort(key=lambda r: (tasks.index(r["task"]), r["scene"], r["member"]))
    result = {
        "settings": settings,
        "overall": figures(records, args.group, judges),
        "per_task": {task: figures([r for r in records if r["task"] == task], args.group, judges) for task in tasks},
        "real_success": float(np.mean([r["success"] for r in records])),
        "real_interactions": sum(r["steps"] for r in records),
        "seconds": round(time.perf_counter() - started, 1),
        "rollouts": records,
    }
    brief = {name: {k: row[k] for k in ("advantage_correlation", "correlation_ci_low", "correlation_ci_high",
                                         "return_correlation", "return_ci_low", "return_ci_high")}
             for name, row in result["overall"].items()}
    print(json.dumps(brief, indent=2))
    write_json(args.out, result)
    args.out.with_suffix(".rollouts.jsonl").unlink()  # every rollout is in --out now


def _played(jobs: list[tuple], settings: dict, log: Path, resume: bool, workers: int) -> list[dict]:
    """Every job's record, each appended to `log` (JSON lines after a line of the settings) as it
    finishes; with `resume`, the records `log` already holds are kept and their jobs not played again."""
    records = []
    if resume and log.exists():
        lines = log.read_text().splitlines()
        if not lines or json.loads(lines[0]) != settings:
            raise SystemExit(f"{log} holds rollouts of other settings; rerun without --resume to start again")
        for line in lines[1:]:
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError:  # the line being written when the run was stopped
                break
    done = {(r["task"], r["scene"], r["member"]) for r in records}
    # Rewritten whole, and atomically, before anything is added: a line cut off above is dropped.
    write_bytes(log, (json.dumps(settings) + "\n" + "".join(json.dumps(r) + "\n" for r in records)).encode())
    with log.open("a") as file:
        for record in parallel_map(play_and_judge, [job for job in jobs if job[:3] not in done], workers):
            file.write(json.dumps(record) + "\n")
            file.flush()
            records.append(record)
    return records


if __name__ == "__main__":
    main()
