"""A learned policy acting in the real world, for evaluation and for recording its rollouts.

Legend: K action-chunk length, A action dimensions (4 in Meta-World), H/W image height/width.

The policy sees the current camera image and returns a chunk of K actions, executed open-loop as
it would be on a robot: these are `gymnast.envs.engine.Actor`s, played by the rollout engine in
`gymnast eval` and `gymnast collect`.
"""

from __future__ import annotations

import functools
import math
import multiprocessing
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gymnast.envs.engine import run_batch
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.envs.metaworld import ACTION_DIM, MetaWorldEnv
from gymnast.utils.images import tile_views

if TYPE_CHECKING:
    from gymnast.policy.base import Policy
    from gymnast.world_model.base import WorldModel


class PolicyActor:
    """A `Policy`: one chunk of K actions per call, from the camera image alone.

    Args:
        policy: the policy.
        temperature: 0 decodes greedily (`Policy.act`); above 0 samples every action token from
            softmax(logits / temperature) (`Policy.sample`).
        noise: standard deviation of Gaussian noise added to every action; 0 adds none.
        seed: seeds the sampling and the noise, so that an episode can be repeated exactly.

    Raises:
        ValueError: a chunk size or action size Meta-World cannot execute, or a negative (or
            non-finite) temperature or noise.
    """

    def __init__(self, policy: Policy, temperature: float = 0.0, noise: float = 0.0, seed: int = 0) -> None:
        import torch

        if policy.chunk_size < 1 or policy.action_dim != ACTION_DIM:
            raise ValueError(
                f"policy has chunk_size={policy.chunk_size}, action_dim={policy.action_dim}; the "
                f"environment needs chunk_size >= 1 and action_dim={ACTION_DIM} (Meta-World's actions)"
            )
        for name, value in (("temperature", temperature), ("noise", noise)):
            if not (value >= 0 and math.isfinite(value)):  # also refuses NaN
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        self._policy, self._temperature, self._noise = policy, temperature, noise
        self._cameras = getattr(getattr(policy, "config", None), "env_cameras", None)  # None: whatever obs["image"] shows
        # Two streams, so the sampled tokens do not depend on whether noise is drawn, and back.
        self._generator = torch.Generator().manual_seed(seed)
        self._rng = np.random.default_rng(seed)

    @property
    def chunk_size(self) -> int:
        """K, the actions of every chunk."""
        return self._policy.chunk_size

    def __call__(self, env: MetaWorldEnv, obs: dict[str, np.ndarray]) -> np.ndarray:
        return self.chunk(self.seen(obs, env.task), env.instruction, env.task, obs.get("state"))

    def seen(self, obs: dict, task: str) -> np.ndarray:
        """What the policy sees of an observation: its cameras side by side. The env may render
        more cameras than the policy sees (its rollouts recorded for a judge of several views)."""
        views = obs.get("images")
        if self._cameras is None or views is None or tuple(views) == self._cameras:
            return obs["image"]
        missing = [name for name in self._cameras if name not in views]
        if missing:
            raise ValueError(f"the policy sees cameras {','.join(self._cameras)}, but the env of {task} renders "
                             f"{','.join(views)}: add {','.join(missing)} to --cameras")
        return tile_views([views[name] for name in self._cameras])

    def chunk(self, image: np.ndarray, instruction: str, task: str, state: np.ndarray | None = None) -> np.ndarray:
        """(K, A) float32 actions in [-1, 1] for one (H, W, 3) uint8 image, real or imagined, and
        the robot's (D,) state where the env has one (a policy that reads none is not given it)."""
        import torch

        from gymnast.policy.base import state_inputs

        image = torch.as_tensor(image)[None]  # (1, H, W, 3) uint8
        states = None if state is None else torch.as_tensor(state, dtype=torch.float32)[None]  # (1, D)
        with torch.inference_mode():
            if self._temperature > 0:
                chunk = self._policy.sample(image, [instruction], self._temperature, self._generator,
                                            **state_inputs(self._policy, states)).actions
            else:
                chunk = self._policy.act(image, [instruction], **state_inputs(self._policy, states))  # (1, K, A)
        expected = (1, self._policy.chunk_size, ACTION_DIM)
        if tuple(chunk.shape) != expected:
            raise ValueError(f"the policy returned shape {tuple(chunk.shape)}, expected (B, K, A) = {expected}")
        actions = chunk[0].detach().to("cpu", torch.float32).numpy()  # (K, A)
        if not np.isfinite(actions).all():
            raise ValueError(f"the policy returned non-finite actions on {task}: {actions.tolist()}")
        if self._noise > 0:
            actions = actions + self._rng.normal(0.0, self._noise, size=actions.shape).astype(np.float32)
        # The environment clips to [-1, 1] anyway; clipping here makes a recorded action the executed one.
        return np.clip(actions, -1.0, 1.0)


class ImaginedPlanActor:
    """The policy plans the whole episode in imagination; the real world then executes the plan.

    At the scene's first frame the policy acts closed loop in the world model (it sees the
    imagined frames, as in world-model RL: the imagined env, driven by the rollout engine's
    `gymnast.envs.engine.run_batch`) for `horizon` actions; the real env executes those
    actions open-loop. The real outcome of the plan is then the true label of an imagined
    rollout: re-imagining the episode's actions from its first frame (as `gymnast train-judge
    --wm` does) gives back the video the policy saw, so such episodes teach a judge what the
    world model's imagined successes and failures really are.

    Args:
        actor: decides each chunk from an imagined frame (its temperature and noise apply there).
        world_model: imagines the frames; its image size must be the env's.
        horizon: actions to plan, at least the episode's limit (a plan that ran out would leave
            the episode unfinished).

    Raises:
        ValueError: a horizon below 1; asked for more actions than the plan holds.
    """

    def __init__(self, actor: PolicyActor, world_model: WorldModel, horizon: int) -> None:
        if horizon < 1:
            raise ValueError(f"an imagined plan needs horizon >= 1, got {horizon}")
        self._actor, self._world_model, self._horizon = actor, world_model, horizon
        self._planned = False

    def __call__(self, env: MetaWorldEnv, obs: dict[str, np.ndarray]) -> np.ndarray:
        import torch

        if self._planned:
            raise ValueError(f"the imagined plan of {self._horizon} actions ran out before the episode on {env.task} "
                             "ended; plan at least the env's horizon")
        self._planned = True
        imagination = BatchedImaginedEnv(self._world_model, 1, self._actor.chunk_size, self._horizon)

        def act(images: np.ndarray, instructions: list[str], states: np.ndarray | None) -> np.ndarray:  # imagined: no state
            return self._actor.chunk(images[0], env.instruction, env.task)[None]

        start = {"frames": obs["image"][None], "instructions": [env.instruction]}  # the first frame only
        with torch.inference_mode():
            plan = [result.actions[:, : result.frames.shape[1]] for result in run_batch(imagination, act, start)]
        return np.concatenate(plan, axis=1)[0]  # (T, A): the last chunk is cut at the horizon


@functools.lru_cache(maxsize=1)
def load_run_world_model(run_dir: str) -> WorldModel:
    """This process's world model from `run_dir` (a run, checkpoint or ensemble), loaded once."""
    from gymnast.world_model.base import load_world_model

    return load_world_model(Path(run_dir))


@functools.lru_cache(maxsize=1)
def load_run_policy(run_dir: str, device: str = "cpu") -> Policy:
    """This process's policy from `run_dir` on `device` (a `gymnast.utils.device` name), loaded
    once and reused across episodes."""
    import torch

    from gymnast.policy.load import load_policy
    from gymnast.utils.device import resolve_device

    if multiprocessing.parent_process() is not None:
        # Each worker is one of several processes on the cores; torch's default of one thread
        # per core in every one of them would oversubscribe the CPU many times over.
        torch.set_num_threads(1)
    return load_policy(Path(run_dir)).to(resolve_device(device))
