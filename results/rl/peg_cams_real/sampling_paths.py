"""The same scenes sampled through both of gymnast's rollout paths, to tell code from scenes.

`gymnast eval --temperature` plays one episode at a time through `PolicyActor`; `gymnast rl` rolls
a batch out through `collect_rollouts` on simulator workers. Both call `Policy.sample`. This runs
one policy at temperature 1.0 on the same N scenes of one task through each, on data seeds
(5000 + i, where RL practises) or evaluation seeds (where `gymnast eval` measures), and prints
the success of each as JSON:

    python results/rl/peg_cams_real/sampling_paths.py results/sft/cameras/policy peg-insert-side-v3 48 data
"""
import json
import sys
import time

import numpy as np
import torch

from gymnast.config import EnvConfig
from gymnast.envs.engine import play_episode
from gymnast.envs.parallel import cached_env
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.envs.starts import scene_starts
from gymnast.envs.tasks import eval_seed
from gymnast.eval.actors import PolicyActor
from gymnast.policy.load import load_policy, policy_env_config
from gymnast.rl.rollout import collect_rollouts


def main() -> None:
    run, task, count, seeds_from = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
    policy = load_policy(run).eval()
    config = policy_env_config(EnvConfig(image_size=policy.config.image_size, horizon=150), policy)
    seeds = [5000 + i for i in range(count)] if seeds_from == "data" else [eval_seed(i) for i in range(count)]
    began = time.time()
    env = cached_env(task, config)
    one_by_one = [play_episode(env, PolicyActor(policy, 1.0, seed=seed), seed).success for seed in seeds]
    starts = scene_starts([(task, seed) for seed in seeds], config)
    with SimVectorEnv(len(starts), policy.chunk_size, config, workers=2) as batch_env:
        batch = collect_rollouts(batch_env, policy, starts, 1.0, torch.Generator().manual_seed(0), every_frame=False)
    print(json.dumps({"task": task, "seeds": seeds_from, "scenes": count,
                      "eval_actor_success": float(np.mean(one_by_one)),
                      "rl_batch_success": batch.success.float().mean().item(), "seconds": time.time() - began}))


if __name__ == "__main__":
    main()
