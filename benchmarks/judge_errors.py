"""Which held-out real cases a trained judge gets wrong, and how near each was to the other side.

The judge run's held-out scenes are read as its training read them (`judge_datasets`,
`split_scenes`) and cut into the cases its metrics count (`judge_cases`: each whole episode, and
each successful one cut halfway to its success and a few steps short of it). Every case the judge
calls wrongly under its own hold rule and threshold is listed with its dataset, task, behaviour
and the judge's probability; for the tasks whose success is one distance (`SUCCESS_RADIUS`:
Meta-World's own points and thresholds), also how close the episode came to success over the
frames the case shows. A false success 2 mm outside the radius is a different problem from one
15 cm away. The object's position is recorded; the tool centre reach measures (between the finger
pads, about 5 cm below the end effector the observation records) is not, so those episodes are
replayed in the simulator from their seed, each step checked against the recording.

    python benchmarks/judge_errors.py --judge runs/headline_three/judge \\
        --out benchmarks/results/judge_errors_headline_three.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from gymnast.data.replay import STATE_TOLERANCE
from gymnast.data.schema import Episode, EpisodeColumns
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.reward.judges.train import judge_datasets, load_judge, saved_judge_config, split_scenes
from gymnast.reward.judges.videos import judge_cases, real_video
from gymnast.utils.atomic import read_json, write_json

# Meta-World's 39-d observation: the end effector at 0:3, the object at 4:7, the goal at 36:39.
OBJECT, GOAL = slice(4, 7), slice(36, 39)
TOOL_CENTRE = "tool centre"
SUCCESS_RADIUS = {"reach-v3": (TOOL_CENTRE, 0.05), "push-v3": (OBJECT, 0.05), "pick-place-v3": (OBJECT, 0.07)}
"""Tasks whose success is one point within a radius (metres) of the goal: the point as a slice of the
observation, or the tool centre, which the observation lacks."""


def tool_centre_path(episode: Episode | EpisodeColumns) -> np.ndarray:
    """(T+1, 3) the tool centre at every frame of a real `episode`, by replaying its actions from its seed.

    Raises:
        ValueError: the episode was not recorded in the real world, or its replay departs from it.
    """
    info = episode.info
    if info.env_variant != "real":
        raise ValueError(f"{info.task} seed {info.seed} was recorded in {info.env_variant!r}, not replayed here")
    env = MetaWorldEnv(info.task, render_mode=None)
    try:
        env.reset(seed=info.seed)
        path = [env.hand_position]
        for step, action in enumerate(episode.actions, start=1):
            env.step(action, observe=False)
            if np.abs(env.env_state - episode.full_states[step]).max() > STATE_TOLERANCE:  # as `collect --replay`
                raise ValueError(f"{info.task} seed {info.seed} departs from its recording at step {step} when replayed")
            path.append(env.hand_position)
    finally:
        env.close()
    return np.stack(path)


def closest_approach(episode: Episode | EpisodeColumns, frames: int) -> dict | None:
    """The smallest distance to the goal over the first `frames` frames of `episode` and its task's
    success radius, in cm; None for a task whose success is not one distance."""
    if episode.info.task not in SUCCESS_RADIUS or episode.full_states.shape[-1] < GOAL.stop:
        return None
    point, radius = SUCCESS_RADIUS[episode.info.task]
    states = episode.full_states[:frames]
    positions = tool_centre_path(episode)[:frames] if point == TOOL_CENTRE else states[:, point]
    distance = np.linalg.norm(positions - states[:, GOAL], axis=1)
    return {"closest_cm": round(100 * float(distance.min()), 1), "success_radius_cm": round(100 * radius, 1)}


def judge_errors(run: Path) -> dict:
    """Every held-out real case the judge `run` calls wrongly, with the counts it was one of."""
    judge = load_judge(run)
    datasets, config = judge_datasets(Path(read_json(run / "config.json")["data"]), saved_judge_config(run))
    errors, positives, negatives = [], 0, 0
    for dataset in datasets:
        for index in split_scenes(dataset, config)[2]:
            episode = dataset.load(index)
            video = real_video(episode)
            for frames, instruction, label, whole, _ in judge_cases([video]):
                positives, negatives = positives + label, negatives + (not label)
                with torch.no_grad():
                    probability = float(judge.probability(frames[None], [instruction])[0])
                if (probability >= judge.config.threshold) == label:
                    continue
                errors.append({"dataset": str(dataset.root), "episode": index, "task": episode.info.task,
                               "behaviour": episode.info.behaviour, "noise": episode.info.noise,
                               "case": "whole" if whole else f"first {len(frames)} frames of {len(video.frames)}",
                               "success": label, "probability": round(probability, 4),
                               "near": closest_approach(episode, len(frames))})
    false_success = [error for error in errors if not error["success"]]
    return {"judge": str(run), "threshold": judge.config.threshold, "hold_steps": judge.config.hold_steps,
            "positives": positives, "negatives": negatives, "missed_successes": len(errors) - len(false_success),
            "false_successes": len(false_success), "errors": errors}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--judge", type=Path, required=True, help="a judge run (gymnast train-judge)")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/judge_errors.json"))
    args = parser.parse_args()
    result = judge_errors(args.judge)
    print(json.dumps(result, indent=2))
    write_json(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
