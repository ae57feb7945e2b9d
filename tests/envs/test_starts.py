"""Start states: evaluation starts are the real first frames of the evaluation seeds."""

import numpy as np

from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.starts import Start, evaluation_starts
from gymnast.envs.tasks import eval_seed

CONFIG = EnvConfig(image_size=96, horizon=60)


def test_evaluation_starts_are_the_real_first_frames_of_evaluation_seeds():
    starts = evaluation_starts(["reach-v3"], 2, CONFIG)
    env = MetaWorldEnv("reach-v3", CONFIG)
    for i, start in enumerate(starts):
        obs, info = env.reset(seed=eval_seed(i))
        assert start.seed == eval_seed(i) and start.instruction == info["instruction"]
        np.testing.assert_array_equal(start.frames, obs["image"][None])
        assert start.reference_actions.shape == (0, 4)


def test_the_tasks_take_turns_in_every_draw_whatever_the_pool_holds():
    import torch

    from gymnast.envs.starts import StartSampler

    frame = np.zeros((1, 8, 8, 3), np.uint8)
    pool = [Start("reach-v3", seed, "reach", frame) for seed in range(5)] + [Start("push-v3", 9, "push", frame)]
    sampler = StartSampler(["reach-v3", "push-v3"], pool, EnvConfig())
    for _ in range(5):
        drawn = sampler(6, torch.Generator().manual_seed(_))
        assert sorted(start.task for start in drawn) == ["push-v3"] * 3 + ["reach-v3"] * 3
    assert {start.seed for _ in range(20) for start in sampler(2, torch.Generator().manual_seed(_))
            if start.task == "reach-v3"} == set(range(5))  # every scene of a task can come up
    assert sampler.rendered == 0  # the pool's frames are already there
