"""World models of several cameras: one single-view model imagines every camera of the robot.

Legend: B batch, V cameras (views), C context frames, K actions per `step` call, H/W one view's
image size, A action dimensions.

A policy of several cameras sees their views side by side, (H, V*W, 3) (`gymnast.utils.images.
tile_views`), and so does everything that carries its frames (the rollout engine, the imagined
env, the videos). `MultiViewWorldModel` takes and returns frames in that layout: it cuts the real
context into the V views, imagines each one from its own frames with one shared single-view model
under the same actions, and puts the imagined views side by side again.

Why one shared model and not one per camera: it is trained on every camera's clips (`gymnast
train-wm --cameras`, each view of an episode a clip of its own under the episode's actions), so
it learns the dynamics once from V times the frames, costs one model's weights, and starts from a
one-camera model's weights (`--init`), which already know the front view. The views are imagined
side by side in one batch of B*V, not jointly: a view does not see the others while it imagines.
What keeps them consistent is that each follows the same actions from its own real frames.

On disk a multi-view model is its single-view backend's checkpoint whose saved model spec adds
``"cameras": [...]`` (`load_world_model` wraps it); a spec without cameras is a one-camera model,
as every model saved before several cameras existed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

from gymnast.utils.images import join_views, split_views
from gymnast.world_model.base import (WorldModel, actions_per_frame, check_actions, check_context, check_states,
                                      grounded_state_dim)


class MultiViewWorldModel(nn.Module):
    """V cameras' views imagined by one single-view world model; implements `WorldModel` with
    frames (B, K, H, V*W, 3), the views side by side in `cameras`' order.

    Args:
        model: the single-view world model (any backend; an ensemble is made of multi-view members,
            `gymnast.world_model.ensemble`, so that each member is loaded as it was trained).
        cameras: the V >= 2 camera names, in the order the frames put them side by side.

    Raises:
        ValueError: fewer than two cameras, or a camera named twice.
    """

    def __init__(self, model: WorldModel, cameras: Sequence[str]) -> None:
        super().__init__()
        cameras = tuple(cameras)
        if len(cameras) < 2 or len(set(cameras)) < len(cameras):
            raise ValueError(f"a multi-view world model needs two or more distinct cameras, got {list(cameras)}")
        self.model, self.cameras = model, cameras

    @property
    def views(self) -> int:
        return len(self.cameras)

    @property
    def context_frames(self) -> int:
        return self.model.context_frames

    @property
    def image_size(self) -> int:
        return self.model.image_size

    @property
    def action_dim(self) -> int:
        return self.model.action_dim

    @property
    def state_dim(self) -> int:
        return grounded_state_dim(self.model)

    @property
    def actions_per_frame(self) -> int:
        return actions_per_frame(self.model)

    @property
    def action_range(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        default = ((-1.0,) * self.action_dim, (1.0,) * self.action_dim)
        return getattr(self.model, "action_range", default)

    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> Any:
        """See `WorldModel.init_state`; `context` is (B, C', H, V*W, 3), the views side by side.
        The state is the single-view model's, of B*V rollouts (an item's V views consecutive)."""
        check_context(context, self.image_size, self.views)
        return self.model.init_state(split_views(context, self.views), generator=generator)

    def step(self, state: Any, actions: torch.Tensor, generator: torch.Generator | None = None,
             states: torch.Tensor | None = None) -> tuple[Any, torch.Tensor]:
        """See `WorldModel.step`: every view applies the same (B, K, A) actions (a grounded model's at
        the same (B, K, S) `states`); returns (B, K, H, V*W, 3)."""
        if isinstance(actions, torch.Tensor):  # else the single-view model's own check names the type
            check_actions(actions, self.action_dim, actions.shape[0])
            check_states(states, self.state_dim, tuple(actions.shape[:2]))
            actions = actions.repeat_interleave(self.views, dim=0)
        grounding = {} if states is None else {"states": states.repeat_interleave(self.views, dim=0)}
        state, frames = self.model.step(state, actions, generator=generator, **grounding)
        return state, join_views(frames, self.views)

    def spec(self) -> dict:
        """The single-view model's spec with the cameras (what `load_world_model` wraps it by)."""
        inner = self.model.spec() if hasattr(self.model, "spec") else {}
        return {**inner, "cameras": list(self.cameras)}


def with_cameras(model: WorldModel, cameras: Sequence[str] | None) -> WorldModel:
    """`model` imagining `cameras` side by side: itself for none or one camera, else wrapped."""
    return MultiViewWorldModel(model, cameras) if cameras and len(cameras) > 1 else model


def model_views(model: Any) -> int:
    """How many cameras' views a world model's frames put side by side (1 for a one-camera model)."""
    return getattr(model, "views", 1)


def model_cameras(model: Any) -> tuple[str, ...]:
    """The cameras a world model imagines, in their side-by-side order; () for a one-camera model,
    which does not record which camera it learnt."""
    return tuple(getattr(model, "cameras", ()))


def replay_cameras(model: Any) -> tuple[str, ...]:
    """The simulator cameras that show the real world as a world model imagines it: its own, or the
    front view for a one-camera model."""
    return model_cameras(model) or ("front",)


def check_policy_views(policy_cameras: Sequence[str], model: Any, policy: Any, wm: Any) -> None:
    """Raises ValueError unless the world model imagines the views the policy sees, side by side in
    the same order (a one-camera policy, `policy_cameras` () or one name, in a one-camera model).

    Args:
        policy_cameras: the policy's cameras (its architecture's ``cameras``).
        model: the world model.
        policy, wm: how the user named them (for the message).
    """
    imagined = model_cameras(model)
    if len(policy_cameras) <= 1 and not imagined:
        return
    if tuple(policy_cameras) != imagined:
        seen = ",".join(policy_cameras) if len(policy_cameras) > 1 else "one camera"
        made = ",".join(imagined) if imagined else "one camera's frames"
        wanted = ",".join(policy_cameras) if len(policy_cameras) > 1 else "NAMES"
        raise ValueError(f"the policy {policy} sees {seen} side by side, but the world model {wm} imagines {made}; "
                         f"practise it in a world model of its cameras (`gymnast train-wm --cameras {wanted}`), "
                         "or with --env real or sim")
