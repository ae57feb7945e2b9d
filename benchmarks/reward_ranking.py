"""Where does a state model's reward lose the ranking GRPO needs: in the imagined states, or in the
reward head itself?

For keyframes of a dataset's episodes, G action sequences are made by adding Gaussian noise to
each keyframe's recorded continuation (a group, as GRPO samples one from a start), every one is
replayed in the real world from the restored keyframe with the simulator's states recorded, and the
group's real dense returns are held against the state model's reward head read two ways: off the
states it imagines under the same actions (what practice uses), and off the *real* states of the
replay (the head's own error alone). Reported: the advantage correlation of each (as `gymnast
rl-signal` computes it) and the spread of the real returns within a group (what the head must
resolve) against the head's per-step error on the real states.

    .venv/bin/python benchmarks/reward_ranking.py --state RUN --data DATA [--tasks ...] [--noise 0.5]
        [--horizon 20] [--group 8] [--out JSON]

Prints and writes --out (default benchmarks/results/reward_ranking.json).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.config import EnvConfig
from gymnast.data.keyframes import KeyframeConfig, dataset_keyframes
from gymnast.data.lerobot import EpisodeDataset
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.policy.text import InstructionEncoder
from gymnast.rl.grpo import group_advantages
from gymnast.utils.atomic import write_json
from gymnast.world_model.state_model import REWARD_SCALE, load_state_model

RESULTS = Path(__file__).parent / "results" / "reward_ranking.json"


def correlation(read: list[list[float]], real: list[list[float]]) -> float:
    """Cosine of the group advantages of (B, G) `read` and `real`."""
    a, _ = group_advantages(torch.tensor(read))
    b, _ = group_advantages(torch.tensor(real))
    return float((a * b).sum() / (a.square().sum().sqrt() * b.square().sum().sqrt()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--state", type=Path, required=True, help="state-model run")
    parser.add_argument("--data", type=Path, required=True, help="dataset whose episodes give the keyframes")
    parser.add_argument("--tasks", default="reach-v3,push-v3,pick-place-v3,peg-insert-side-v3")
    parser.add_argument("--noise", type=float, default=0.5, help="std of the noise added to the continuation")
    parser.add_argument("--horizon", type=int, default=20, help="actions per segment")
    parser.add_argument("--group", type=int, default=8, help="action sequences per keyframe")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    model, encoder = load_state_model(args.state), InstructionEncoder()
    dataset = EpisodeDataset(args.data)
    episodes = [i for i, info in enumerate(dataset.episodes) if info.task in args.tasks.split(",")]
    starts = dataset_keyframes(dataset, episodes, KeyframeConfig(sampling="uniform", horizon=args.horizon), args.seed)
    rng, envs = np.random.default_rng(args.seed), {}
    real, on_imagined, on_real, errors = [], [], [], []
    for start in starts:
        env = envs.get(start.task) or envs.setdefault(start.task, MetaWorldEnv(
            start.task, config=EnvConfig(image_size=32, horizon=10**6, terminate_on_success=False)))
        reference = np.zeros((args.horizon, 4), np.float32)
        reference[: len(start.reference_actions)] = start.reference_actions
        actions = np.clip(reference + rng.normal(0, args.noise, (args.group, args.horizon, 4)), -1, 1).astype(np.float32)
        returns, states, rewards = [], [], []
        for sequence in actions:
            env.reset(seed=start.seed, options={"prefix": start.prefix})
            steps = [env.step(action) for action in sequence]
            rewards.append([r / REWARD_SCALE for _, r, *_ in steps])
            returns.append(float(np.mean(rewards[-1])))
            states.append(np.stack([info["env_state"] for *_, info in steps]))
        embedding = encoder([start.instruction] * args.group)
        first = torch.from_numpy(np.repeat(start.state[None], args.group, 0))
        last = start.prefix[-1] if len(start.prefix) else np.zeros(4, np.float32)
        imagined = model.imagine(first, torch.from_numpy(actions), embedding,
                                 torch.from_numpy(np.repeat(last[None], args.group, 0)))
        with torch.no_grad():
            text = model.embed_text(embedding)[:, None].expand(-1, args.horizon, -1)
            head, _ = model.read_reward(torch.from_numpy(np.stack(states)).float(),
                                        first[:, None].expand(-1, args.horizon, -1), text)
        real.append(returns)
        on_imagined.append(imagined.rewards.mean(1).tolist())
        on_real.append(head.mean(1).tolist())
        errors.append(float((head - torch.tensor(rewards)).square().mean().sqrt()))
    for env in envs.values():
        env.close()
    result = {
        "state": str(args.state), "data": str(args.data), "tasks": args.tasks, "noise": args.noise,
        "horizon": args.horizon, "group": args.group, "groups": len(starts),
        "correlation_head_on_imagined_states": round(correlation(on_imagined, real), 3),
        "correlation_head_on_real_states": round(correlation(on_real, real), 3),
        "real_return_std_within_group": round(float(np.std(np.array(real), axis=1).mean()), 4),
        "head_step_error_on_real_states": round(float(np.mean(errors)), 4),
    }
    print(json.dumps(result, indent=2))
    write_json(args.out, result)


if __name__ == "__main__":
    main()
