"""WorldGym: can the world model and its judge rank policies without the real world?

Each policy's success is estimated in imagination (greedy rollouts from the real first frames of
evaluation seeds, judged by the learned judge) and compared with its success in the real world,
over policies of different quality; WorldGym (World-Gymnast's evaluation) reports the
correlation between the two.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from gymnast.config import EnvConfig

logger = logging.getLogger(__name__)


def imagined_success(policy_run: Path, wm_run: Path, judge_run: Path, tasks: str, episodes: int,
                     batch: int = 32) -> dict:
    """Judged success of greedy imagined rollouts from `episodes` evaluation seeds per task:
    ``success``, ``ci_low``, ``ci_high``, ``episodes`` and ``per_task``."""
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.policy.vla import load_policy
    from gymnast.reward.select import make_reward
    from gymnast.rl.evaluate import EnvFactory, evaluate_in_env, evaluation_starts
    from gymnast.world_model.base import load_world_model

    policy, world_model = load_policy(policy_run), load_world_model(wm_run)
    judge = make_reward(f"judge:{judge_run}")
    task_list = resolve_tasks(tasks)
    env_config = EnvConfig(image_size=policy.config.image_size)
    starts = evaluation_starts(task_list, episodes, env_config)
    envs = EnvFactory("imagined", policy.chunk_size, env_config, "none", 1, world_model)
    try:
        envs.train(min(batch, len(starts)))
        values = evaluate_in_env(envs, "imagined", policy, judge, starts, prefix="wg")
    finally:
        envs.close()
    return {"success": values["wg_success"], "ci_low": values["wg_ci_low"], "ci_high": values["wg_ci_high"],
            "episodes": int(values["wg_episodes"]),
            "per_task": {task: values[f"wg_success/{task}"] for task in task_list}}


def correlation(imagined: list[float], real: list[float]) -> dict:
    """Pearson and Spearman correlation of imagined with real success over policies (None where
    undefined: fewer than three policies, or one side constant)."""
    from scipy import stats

    if len(imagined) != len(real):
        raise ValueError(f"{len(imagined)} imagined estimates but {len(real)} real ones")
    if len(imagined) < 3 or len(set(imagined)) < 2 or len(set(real)) < 2:
        return {"pearson": None, "spearman": None}
    pearson = float(stats.pearsonr(imagined, real).statistic)
    spearman = float(stats.spearmanr(imagined, real).statistic)
    return {"pearson": None if math.isnan(pearson) else pearson, "spearman": None if math.isnan(spearman) else spearman}
