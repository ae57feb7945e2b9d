"""An ensemble of world models that says where its members disagree.

Legend: M members, B batch, K actions per `step` call, H/W image size.

All members start from the same context and step under the same actions. The frames the ensemble
returns are its first member's, not the members' mean: the mean of several blurry frames is
blurrier still (an arm in two places becomes two ghost arms), and returning one member's frames
means swapping a model for an ensemble led by it changes nothing the policy, the reward or the
fidelity figures see. What the ensemble adds is `EnsembleState.disagreement`, per imagined frame,
so a rollout can be discounted or stopped where the members part ways: where they disagree, at
least one of them is wrong.

On disk an ensemble is a directory holding ``ensemble.json`` (`ENSEMBLE_FILE`):

    {"backend": "ensemble", "members": ["../wm_seed0", "../wm_seed1"]}

Members are world-model runs or checkpoints (anything `load_world_model` loads), relative to that
directory or absolute; `write_ensemble` (``gymnast make-ensemble``) writes one.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from gymnast.utils.atomic import read_json, write_json
from gymnast.world_model.base import (ENSEMBLE_FILE, WorldModel, actions_per_frame, check_context, grounded_state_dim,
                                      load_world_model)
from gymnast.world_model.views import model_cameras, model_views


@dataclass(frozen=True)
class EnsembleState:
    """Where a batch of ensemble rollouts stands.

    Attributes:
        members: each member's own state, in member order.
        disagreement: (B, K) float32, the members' disagreement on each frame of the last `step`
            call (`frame_disagreement`); None before the first step.
    """

    members: tuple[Any, ...]
    disagreement: torch.Tensor | None = None


def frame_disagreement(frames: Sequence[torch.Tensor]) -> torch.Tensor:
    """How far apart the members' frames are: M tensors (B, K, H, W, 3) uint8 -> (B, K) float32.

    The standard deviation across members of each pixel channel (population, so two members give
    half their difference), in [0, 1] units, averaged over the pixels and channels. 0 means all
    members imagined the same frame.
    """
    stacked = torch.stack([f.float() / 255.0 for f in frames])  # (M, B, K, H, W, 3)
    return stacked.std(dim=0, correction=0).mean(dim=(-3, -2, -1))


class EnsembleWorldModel(nn.Module):
    """Several world models stepped together; implements `gymnast.world_model.base.WorldModel`.

    Args:
        members: two or more world models (nn.Modules) making frames of one size from one action space.

    Raises:
        ValueError: fewer than two members, or their image sizes, action dimensions or cameras differ.
    """

    backend = "ensemble"

    def __init__(self, members: Sequence[WorldModel]) -> None:
        super().__init__()
        if len(members) < 2:
            raise ValueError(f"an ensemble needs at least two members, got {len(members)}")
        for name, values in (("image_size", [m.image_size for m in members]), ("action_dim", [m.action_dim for m in members]),
                             ("cameras", [model_cameras(m) for m in members]),
                             ("state_dim", [grounded_state_dim(m) for m in members]),
                             ("actions_per_frame", [actions_per_frame(m) for m in members])):
            if len(set(values)) > 1:
                raise ValueError(f"the members' {name} differ: {values}")
        self.members = nn.ModuleList(members)

    @property
    def context_frames(self) -> int:
        return max(m.context_frames for m in self.members)  # each member keeps the most recent it needs

    @property
    def image_size(self) -> int:
        return self.members[0].image_size

    @property
    def views(self) -> int:
        return model_views(self.members[0])

    @property
    def cameras(self) -> tuple[str, ...]:
        return model_cameras(self.members[0])

    @property
    def action_dim(self) -> int:
        return self.members[0].action_dim

    @property
    def state_dim(self) -> int:
        return grounded_state_dim(self.members[0])

    @property
    def actions_per_frame(self) -> int:
        return actions_per_frame(self.members[0])

    @property
    def action_range(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The first member's (see `EmbeddedWorldModel.action_range`)."""
        default = ((-1.0,) * self.action_dim, (1.0,) * self.action_dim)
        return getattr(self.members[0], "action_range", default)

    def init_state(self, context: torch.Tensor, generator: torch.Generator | None = None) -> EnsembleState:
        """See `WorldModel.init_state`: every member starts from the same context."""
        check_context(context, self.image_size, self.views)
        return EnsembleState(tuple(m.init_state(context, generator=generator) for m in self.members))

    @torch.inference_mode()
    def step(self, state: EnsembleState, actions: torch.Tensor, generator: torch.Generator | None = None,
             states: torch.Tensor | None = None) -> tuple[EnsembleState, torch.Tensor]:
        """See `WorldModel.step`: every member applies the actions (grounded members at the same
        `states`); returns the first member's frames.

        The members' disagreement on these frames is in the returned state's `disagreement`.
        """
        grounding = {} if states is None else {"states": states}
        states, frames = zip(*(m.step(s, actions, generator=generator, **grounding) for m, s in zip(self.members, state.members)))
        return EnsembleState(tuple(states), frame_disagreement(frames)), frames[0]

    def spec(self) -> dict:
        """The members' specs (a description for reports; an ensemble loads from its directory)."""
        return {"backend": self.backend, "members": [m.spec() if hasattr(m, "spec") else None for m in self.members]}

    @classmethod
    def load(cls, directory: Path, **overrides: Any) -> EnsembleWorldModel:
        """The ensemble described by ``directory/ensemble.json``, each member through `load_world_model`.

        `overrides` go to every member (see `load_world_model`).
        """
        return cls([load_world_model(path, **overrides) for path in member_paths(directory)])


def is_ensemble(path: str | Path) -> bool:
    """Whether `path` is an ensemble directory (holds ``ensemble.json``)."""
    return (Path(path) / ENSEMBLE_FILE).is_file()


def member_paths(directory: str | Path) -> list[Path]:
    """The member runs listed in ``directory/ensemble.json``, relative ones resolved against it.

    Raises:
        ValueError: the file is not an ensemble description.
    """
    path = Path(directory) / ENSEMBLE_FILE
    manifest = read_json(path)
    if not isinstance(manifest, dict):
        manifest = {}
    members = manifest.get("members")
    if manifest.get("backend") != EnsembleWorldModel.backend or not isinstance(members, list) or len(members) < 2:
        raise ValueError(f'{path}: expected {{"backend": "ensemble", "members": [two or more run paths]}}')
    return [Path(directory) / member for member in members]  # an absolute member stays absolute


def write_ensemble(out: Path, members: Sequence[Path]) -> EnsembleWorldModel:
    """Writes the ensemble directory `out` (``ensemble.json``) over member runs; returns it loaded.

    Members are stored relative to `out`, so the runs and the ensemble can move together. Loading
    the ensemble first checks that the members load and fit together.

    Raises:
        FileNotFoundError: a member has no checkpoint.
        ValueError: fewer than two members, or they make different frames or take different actions.
    """
    model = EnsembleWorldModel([load_world_model(member) for member in members])
    write_manifest(out, members)
    return model


def write_manifest(out: Path, members: Sequence[Path]) -> None:
    """Writes ``out/ensemble.json`` listing `members` relative to `out` (the runs and the ensemble
    can move together); the caller has checked that they load and fit together."""
    out = Path(out)
    relative = [os.path.relpath(Path(member).absolute(), out.absolute()) for member in members]
    write_json(out / ENSEMBLE_FILE, {"backend": EnsembleWorldModel.backend, "members": relative})
