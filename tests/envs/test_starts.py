"""Start states: evaluation starts are the real first frames of the evaluation seeds."""

import numpy as np

from gymnast.config import EnvConfig
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.starts import evaluation_starts
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
