"""The real world: a Meta-World v3 task as a Gymnasium environment that returns camera images.

The policy sees only what a camera on a real robot would give it (an RGB image and the hand's
proprioception) plus a language instruction; the full simulator state is reported in `info` for
scripted experts, datasets and analysis, never in the observation.

`(task, seed)` fixes the initial state, so identical actions give identical frames. The same class
plays the software simulator when built with a `SimGap` other than ``none``.

Cameras: the env renders the views `EnvConfig.cameras` names (`gymnast.envs.cameras`), and only
those, each costing one more render per step. ``obs["images"]`` maps every view's name to its
frame, in that order; ``obs["image"]`` is the views side by side, (H, V*W, 3)
(`gymnast.utils.images.tile_views`), which is what the policy, the world model, the judge and the
rollout engine read. With the default ``("front",)`` it is the one camera's frame, the same array,
as it has always been; a dataset records each view as its own video.
"""

from __future__ import annotations

import zlib
from typing import Any, Iterator

import gymnasium as gym
import numpy as np
from metaworld.env_dict import ALL_V3_ENVIRONMENTS

from gymnast.config import EnvConfig
from gymnast.envs.cameras import camera_pose
from gymnast.envs.gap import SimGap, apply_gap, get_gap
from gymnast.envs.instructions import GOAL_MARKER_TASKS, instruction_for
from gymnast.envs.perturb import Perturbation, get_perturbation, random_offset
from gymnast.envs.render import Marker, SceneRenderer
from gymnast.envs.tasks import DATA_SEEDS, check_task
from gymnast.utils.images import tile_views

ACTION_DIM = 4
STATE_DIM = 4  # hand xyz + gripper opening
CONTROL_FPS = 80  # actions (and rendered frames) per second: Meta-World's 12.5 ms control step
ENV_STATE_DIM = 39  # Meta-World's full observation vector
# Rejection sampling inside Meta-World's reset_model asks for new layouts until objects are far
# enough apart; a perturbed layout that keeps failing that test gets a new direction this often.
_MAX_LAYOUT_TRIES = 100


class MetaWorldEnv(gym.Env):
    """One Meta-World v3 task, observed through a camera.

    Observation: ``{"image": (H, V*W, 3) uint8, "images": {camera: (H, W, 3) uint8}, "state": (4,)
    float32}``; ``image`` is the V cameras' frames side by side (see the module docstring).
    Action: (4,) float32 in [-1, 1]: hand displacement xyz (scaled by 1 cm) and gripper effort.
    Reward: Meta-World's dense shaped reward. ``terminated`` means the task succeeded (when
    `EnvConfig.terminate_on_success`), ``truncated`` that the horizon was reached.
    ``info`` holds ``success``, ``instruction``, ``task``, ``seed``, ``step`` and ``env_state``.

    Args:
        task: Meta-World v3 task name, e.g. ``drawer-open-v3``.
        config: image size, horizon and cameras.
        gap: ``none`` (the real world), ``mild``, ``strong`` or a custom `SimGap`.
        perturbation: e.g. ``minor``, ``major:object`` or a `Perturbation`.
        instruction_split: ``train`` or ``heldout`` paraphrases of the instruction.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": CONTROL_FPS}

    def __init__(
        self,
        task: str,
        config: EnvConfig | None = None,
        gap: str | SimGap = "none",
        perturbation: str | Perturbation = "none",
        instruction_split: str = "train",
        render_mode: str | None = "rgb_array",
    ) -> None:
        self.task = check_task(task)
        self.config = config or EnvConfig()
        self.gap = get_gap(gap)
        self.perturbation = get_perturbation(perturbation)
        self.instruction_split = instruction_split
        self.render_mode = render_mode

        self._mw = ALL_V3_ENVIRONMENTS[self.task]()
        self._mw._partially_observable = False  # the goal is needed by the experts and datasets
        del self._mw.sawyer_observation_space  # cached for the old observability
        self._mw._set_task_called = True
        self._mw.max_path_length = np.iinfo(np.int64).max  # the horizon is enforced here
        # Every reset asks this env for the layout (object and goal positions) to use.
        self._mw._get_state_rand_vec = self._next_layout
        self._layouts: Iterator[np.ndarray] = iter(())
        self._has_goal = self._mw._random_reset_space.low.size == 6
        if self.perturbation.target == "goal" and self.perturbation.active and not self._has_goal:
            raise ValueError(
                f"task {self.task!r} has no goal position independent of its object, so a goal "
                "perturbation is undefined; use target 'object', 'robot' or 'all'"
            )
        self._default_hand_init = np.array(self._mw.hand_init_pos, dtype=np.float64)
        apply_gap(self._mw.model, self.gap)
        self._mw.action_scale *= self.gap.action_scale

        size = self.config.image_size
        # Same task, same gap: the same XML with the same visual edits, so one GL context serves
        # all, every view of every env of the scene in this process included.
        self._renderers = {
            name: SceneRenderer(self._mw.model, size, size, camera_pose(name, self.config, self.gap, np.zeros(3)),
                                share=(self.task, self.gap))
            for name in self.config.cameras
        }
        self._renderer = self._renderers[self.config.cameras[0]]  # the primary view
        image_space = gym.spaces.Box(0, 255, (size, size, 3), np.uint8)
        self.observation_space = gym.spaces.Dict(
            {
                "image": gym.spaces.Box(0, 255, (size, len(self.config.cameras) * size, 3), np.uint8),
                "images": gym.spaces.Dict({name: image_space for name in self.config.cameras}),
                "state": gym.spaces.Box(
                    np.append(self._mw._HAND_SPACE.low, -1.0).astype(np.float32),
                    np.append(self._mw._HAND_SPACE.high, 1.0).astype(np.float32),
                ),
            }
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        self._task_key = zlib.crc32(self.task.encode())
        self._episode_seed: int | None = None
        self._instruction = ""
        self._steps = 0
        self._env_state = np.zeros(ENV_STATE_DIM)
        self._frame: np.ndarray | None = None

    # -- Gymnasium API -----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts an episode from the initial state fixed by (task, seed).

        Args:
            seed: the episode seed; when None, one is drawn from the data seed range with the
                env's own generator (seeded by an earlier ``reset(seed=...)``).
            options: ``{"instruction": str}`` overrides the instruction for this episode;
                ``{"prefix": (T0, A) actions}`` restores a keyframe: the actions are replayed from
                the scene's initial state (Meta-World is deterministic, so the state is exactly
                the one the recording passed through) and the episode starts there, with its
                step count and horizon counted from the keyframe. ``info["prefix_steps"]`` says
                how many real actions the restore took.

        Raises:
            ValueError: the prefix is not a (T0, A) array of finite actions.
        """
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(DATA_SEEDS.start, DATA_SEEDS.stop))
        self._episode_seed = int(seed)
        self._place_scene(self._episode_seed)
        options = options or {}
        self._instruction = options.get("instruction") or instruction_for(
            self.task, self._episode_seed, self.instruction_split
        )
        prefix = check_prefix(options.get("prefix"))
        for action in prefix:  # not observed: only the keyframe is rendered
            mw_obs, *_ = self._mw.step(np.clip(action, -1.0, 1.0))
            self._env_state = np.asarray(mw_obs, dtype=np.float64)
        self._steps = 0
        return self._observe(), self._info(success=False) | {"prefix_steps": len(prefix)}

    def step(self, action, observe: bool = True):
        """Gymnasium's step. With ``observe=False`` (the rollout engine's steps inside an open-loop
        chunk whose frames nobody records) the cameras are not rendered, the costliest part of a
        step: the observation's ``image`` and ``images`` are None, unless the step ends the episode."""
        if self._episode_seed is None:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (ACTION_DIM,):
            raise ValueError(f"action must have shape ({ACTION_DIM},), got {action.shape}")
        mw_obs, reward, _, _, mw_info = self._mw.step(np.clip(action, -1.0, 1.0))
        self._env_state = np.asarray(mw_obs, dtype=np.float64)
        self._steps += 1
        success = bool(mw_info["success"])
        terminated = success and self.config.terminate_on_success
        truncated = not terminated and self._steps >= self.config.horizon
        obs = self._observe() if observe or terminated or truncated else self._unobserved()
        return obs, float(reward), terminated, truncated, self._info(success)

    def render(self) -> np.ndarray:
        if self._episode_seed is None:
            raise RuntimeError("call reset() before render()")
        if self._frame is None:  # the last step was not observed: render the scene as it is now
            self._observe()
        return self._frame

    def close(self) -> None:
        for renderer in self._renderers.values():
            renderer.close()

    # -- what else the project needs ------------------------------------------------------------

    @property
    def instruction(self) -> str:
        return self._instruction

    @property
    def env_state(self) -> np.ndarray:
        """(39,) float64 Meta-World observation: hand, gripper, objects, previous frame, goal."""
        return self._env_state

    @property
    def goal_position(self) -> np.ndarray:
        return np.array(self._mw._target_pos, dtype=np.float64)

    @property
    def hand_position(self) -> np.ndarray:
        return np.array(self._mw.tcp_center, dtype=np.float64)

    @property
    def mujoco_model(self):
        return self._mw.model

    @property
    def mujoco_data(self):
        return self._mw.data

    def markers(self) -> list[Marker]:
        """Scene-only spheres that make an otherwise invisible goal point visible."""
        if self.task not in GOAL_MARKER_TASKS:
            return []
        return [Marker(position=tuple(self._mw._target_pos))]

    def segmentation(self) -> np.ndarray:
        """(H, W, 2) per-pixel (object id, object type) of the primary view's current frame; see SceneRenderer."""
        return self._renderer.render_segmentation(self._mw.data, self.markers())

    # -- internals -----------------------------------------------------------------------------

    def _next_layout(self) -> np.ndarray:
        try:
            layout = next(self._layouts)
        except StopIteration:
            raise RuntimeError(
                f"no valid initial layout for {self.task!r} with perturbation {self.perturbation}"
            ) from None
        self._mw._last_rand_vec = layout
        return layout

    def _place_scene(self, seed: int) -> None:
        rng = np.random.default_rng([self._task_key, seed])
        self._layouts = _uniform_layouts(rng, self._mw._random_reset_space)
        self._reset_simulator(self._default_hand_init)
        if not self.perturbation.active:
            return
        # The perturbation starts from the unperturbed layout of the same seed, so "minor"
        # means 2.5 cm away from exactly the state an unperturbed episode would start in.
        base = self._mw._last_rand_vec.copy()
        offsets = np.random.default_rng([self._task_key, seed, 1])
        distance = self.perturbation.distance_m
        hand = self._default_hand_init.copy()
        if self.perturbation.moves("robot"):
            hand += random_offset(offsets, distance, planar=False)

        def perturbed_layouts() -> Iterator[np.ndarray]:
            for _ in range(_MAX_LAYOUT_TRIES):
                layout = base.copy()
                if self.perturbation.moves("object"):
                    layout[:3] += random_offset(offsets, distance, planar=True)
                if self.perturbation.moves("goal") and self._has_goal:
                    layout[3:6] += random_offset(offsets, distance, planar=True)
                yield layout

        self._layouts = perturbed_layouts()
        self._reset_simulator(hand)

    def _reset_simulator(self, hand_init: np.ndarray) -> None:
        self._mw.hand_init_pos = hand_init
        mw_obs, _ = self._mw.reset()
        self._env_state = np.asarray(mw_obs, dtype=np.float64)

    def _observe(self) -> dict[str, Any]:
        markers, gripper = self.markers(), self._mw.tcp_center
        images = {}
        for name, renderer in self._renderers.items():
            renderer.camera = camera_pose(name, self.config, self.gap, gripper)  # the gripper view moves
            images[name] = renderer.render(self._mw.data, markers)
        self._frame = tile_views([images[name] for name in self.config.cameras])
        return {"image": self._frame, "images": images, "state": self._env_state[:STATE_DIM].astype(np.float32)}

    def _unobserved(self) -> dict[str, Any]:
        """`_observe`'s observation without rendering: the robot's state, no images."""
        self._frame = None  # stale now; `render` draws it when asked
        return {"image": None, "images": None, "state": self._env_state[:STATE_DIM].astype(np.float32)}

    def _info(self, success: bool) -> dict[str, Any]:
        return {
            "success": success,
            "instruction": self._instruction,
            "task": self.task,
            "seed": self._episode_seed,
            "step": self._steps,
            "env_state": self._env_state.astype(np.float32),
        }


def check_prefix(prefix: Any) -> np.ndarray:
    """A keyframe's prefix as (T0, A) float32 actions (none: (0, A)), or ValueError naming its shape."""
    if prefix is None:
        return np.zeros((0, ACTION_DIM), np.float32)
    actions = np.asarray(prefix, dtype=np.float32)
    if actions.ndim != 2 or actions.shape[1] != ACTION_DIM:
        raise ValueError(f"a keyframe prefix must be (T0, {ACTION_DIM}) actions, got shape {actions.shape}")
    if not np.isfinite(actions).all():
        raise ValueError("a keyframe prefix must hold finite actions")
    return actions


def _uniform_layouts(rng: np.random.Generator, space: gym.spaces.Box) -> Iterator[np.ndarray]:
    """Endless layouts drawn as Meta-World draws them, but from our seeded generator."""
    while True:
        yield rng.uniform(space.low, space.high)
