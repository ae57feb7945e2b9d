"""Real rollouts seen through a world model that is restarted from the real frame every few actions.

Legend: B batch (parallel rollouts), K actions per chunk (one env step), C context frames, H/W
image size, A action dimensions.

The learning ladder's imagined sight (R3) lets the policy act on imagined frames for a whole
episode, and what it learns there carries over to real frames only in part (docs/rl.md, "Where
learning dies"). Two things change over those 150 actions at once: the frames are the world
model's, and the world model drifts further from the real scene with every action it imagines.
`AnchoredImaginedEnv` pulls them apart. Its rollouts happen in the real world (the actions, the
success and the rewards are the real world's, and count as real interactions), while the policy
sees them through the world model, which restarts from the real frame those actions reached
every `every` actions. The policy reads the frame at the end of each chunk: every `every` actions
that is the real frame itself, and in between the world model's, imagined at most `every` - K
actions past the last real one. `every` = K shows it the real world alone (a control: it learns as
RL in the real world does); `every` = 2K real and imagined frames in turn; the horizon R3's
whole-episode imagination.

It keeps the contract of `gymnast.envs.sim_vector.SimVectorEnv` (one step is a (B, K, A) chunk,
its frames in ``infos["frames"]``, no autoreset, the simulator's ``rewards``, ``success`` and
``executed``), so the RL loop drives it like any other env. The frames it reports are the ones
the policy saw: imagined, the chunk's last one real where the world model restarted.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from gymnast.envs.imagined import BatchedImaginedEnv, hold_after_end
from gymnast.envs.metaworld import CONTROL_FPS
from gymnast.envs.sim_vector import SimVectorEnv

REAL_INFOS = ("instruction", "step", "task", "seed", "success", "prefix_steps", "rewards", "executed", "env_states")
"""What the real world reports of the rollouts: everything but the frames the policy sees."""


class AnchoredImaginedEnv(VectorEnv):
    """B real rollouts the policy sees through a world model restarted from the real frame every
    `every` actions (see the module docstring).

    Observation: ``{"image": (B, H, W, 3) uint8}``, what the world model imagines (no robot state:
    the real one would show the policy the world it does not see). Action: (B, K, A) float32 in
    [-1, 1]. Rewards, terminations and infos are the real world's (`SimVectorEnv`), but
    ``frames``: (B, K, H, W, 3) the imagined ones, after a rollout's end its last frame repeated,
    and ``disagreement`` where the world model reports it.

    Args:
        imagined: the world model's env, B rollouts; closed with this one.
        real: the real world's, the same B and chunk; closed with this one.
        every: actions between restarts, a multiple of the chunk K.

    Raises:
        ValueError: envs of different sizes or chunks, or `every` not a positive multiple of K.
    """

    metadata = {"autoreset_mode": AutoresetMode.DISABLED, "render_modes": [], "render_fps": CONTROL_FPS}

    def __init__(self, imagined: BatchedImaginedEnv, real: SimVectorEnv, every: int) -> None:
        chunk = real.single_action_space.shape[0]
        if imagined.num_envs != real.num_envs or imagined.single_action_space.shape != real.single_action_space.shape:
            raise ValueError(f"the imagined and the real env must step the same rollouts and chunks: "
                             f"{imagined.num_envs} x {imagined.single_action_space.shape} against "
                             f"{real.num_envs} x {real.single_action_space.shape}")
        if every < chunk or every % chunk:
            raise ValueError(f"the world model restarts from the real frame between chunks: every must be a positive "
                             f"multiple of the policy's chunk of {chunk} actions, got {every}")
        self.imagined, self.real, self.every = imagined, real, every
        self.num_envs = real.num_envs
        self.single_observation_space, self.observation_space = imagined.single_observation_space, imagined.observation_space
        self.single_action_space, self.action_space = real.single_action_space, real.action_space
        self._since = 0  # actions imagined since the last real frame
        self._shown: np.ndarray | None = None  # (B, H, W, 3) each rollout's latest frame

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts the B real rollouts (``options`` as `SimVectorEnv.reset` reads them) and imagines
        from their first frames (``options["frames"]``, as `BatchedImaginedEnv.reset` reads them)."""
        super().reset(seed=seed)
        _, infos = self.real.reset(seed=seed, options=options)
        obs, _ = self.imagined.reset(seed=seed, options=options)
        self._since, self._shown = 0, obs["image"]
        return obs, infos

    def step(self, actions):
        """Takes the chunk in the real world and imagines it; restarts the world model from the real
        frames when `every` actions have been imagined since the last."""
        _, rewards, terminated, truncated, infos = self.real.step(actions)
        *_, imagined = self.imagined.step(actions)  # its horizon is the real world's: the real world ends it
        frames = np.array(imagined["frames"])  # a copy: the imagined env keeps its own as the video
        self._since += frames.shape[1]
        if self._since >= self.every:
            frames[:, -1] = self.imagined.restart(infos["frames"][:, -1:])
            self._since = 0
        hold_after_end(frames, infos["executed"], self._shown)  # ended, now or before, in the real world
        self._shown = frames[:, -1].copy()
        shown = {key: infos[key] for key in REAL_INFOS if key in infos} | {"frames": frames}
        if "disagreement" in imagined:
            shown["disagreement"] = imagined["disagreement"]
        return {"image": frames[:, -1].copy()}, rewards, terminated, truncated, shown

    def close_extras(self, **kwargs: Any) -> None:
        self.imagined.close()
        self.real.close()
