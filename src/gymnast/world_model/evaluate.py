"""`gymnast eval-wm`: how faithful is a world model on episodes it never trained on?

For every held-out episode (scenes kept out of training, see `gymnast.world_model.data`) the model
starts from real context frames at several points of the episode (t = 0, 32, 64, ...) and imagines
open-loop, under the episode's real actions, to the episode's end. Each imagined frame is compared
with the real one: PSNR, SSIM and a perceptual distance, and PSNR over the moving pixels only
(where the real frame differs from the first context frame; the static table otherwise flatters
whole-frame PSNR). The same figures are computed for the trivial predictor that repeats the last
context frame, which the model must beat. Horizon h means the h-th imagined frame; "full" is the
mean over every frame of the rollouts that start at t = 0, i.e. whole episodes.

A world model of several cameras (`gymnast.world_model.views`) is measured on their views side by
side, and on each camera's view alone (``per_camera``): the gripper camera's view changes far more
than the front one's as the hand moves, so the two fail differently.

A grounded model (one that renders every frame at a state, `gymnast.world_model.grounding`) is
measured at the recorded states, or at a state model's (``robot_state``): ``grounding`` says which.

For an ensemble (`gymnast.world_model.ensemble`) the frames measured are its first member's, and
the report adds the members' per-frame disagreement (disagreement_h1 ... _full) and how well it
predicts that member's error (see `disagreement_error`): the evidence for stopping or discounting
imagined rollouts where the members disagree. Held out for an ensemble are the scenes held out of
every member (the smallest of their held-out fractions: the scene hash is the same for all).

Legend: N rollouts, T imagined frames, H/W image size.
"""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from gymnast.data.frames import Fit, model_image_size
from gymnast.data.lerobot import EpisodeDataset, FeatureKeys
from gymnast.utils.atomic import read_json, write_json
from gymnast.utils.checkpoint import resolve_checkpoint
from gymnast.utils.device import resolve_device
from gymnast.utils.images import split_views
from gymnast.utils.plugins import is_plugin
from gymnast.world_model.base import (actions_per_frame, every_nth_frame, grounded_state_dim, load_world_model, placed,
                                      rollout)
from gymnast.world_model.controllability import ControllabilityConfig, check_controllability
from gymnast.world_model.data import split_episodes
from gymnast.world_model.ensemble import is_ensemble, member_paths
from gymnast.world_model.grounding import StateSource
from gymnast.world_model.state_model import load_state_models
from gymnast.world_model.metrics import PerceptualDistance, masked_psnr, moving_mask, pearson, psnr, ssim, summarize_horizons, to_unit_float
from gymnast.world_model.videos import side_by_side, write_gif, write_side_by_side
from gymnast.world_model.views import model_cameras

logger = logging.getLogger(__name__)

MEASURES = ("psnr", "ssim", "perceptual", "moving_psnr")


@dataclass(frozen=True)
class WorldModelEvalConfig:
    """What eval-wm measures."""

    max_episodes: int = 0
    """Evaluate at most this many held-out episodes (0 = all of them)."""
    start_every: int = 32
    """Open-loop rollouts start at t = 0, start_every, 2 * start_every, ... of each episode."""
    videos: int = 6
    """Side-by-side videos (real | imagined | difference) of whole held-out episodes."""
    gifs: int = 0
    """Also write the first this many of them as small looping GIFs (for docs and web pages)."""
    controllability: ControllabilityConfig = ControllabilityConfig()
    """The check that different actions give the simulator's different futures."""
    reanchor_every: int | None = None
    """Override the embedded model's re-anchoring period (0 = never; None = as trained)."""
    camera: str | None = None
    """Camera to read from the dataset (e.g. ``front``); default: its first video (else image) feature."""
    keys: FeatureKeys = FeatureKeys()
    """Which dataset features are the actions and the states (--action-key, --state-key)."""
    device: str = "auto"
    """Where the world model imagines: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N."""
    robot_state: Path | None = None
    """For a grounded world model: the state model (or ensemble) run whose imagined states it renders
    at, from each rollout's real start (what practice gives it); default: the recorded states."""
    measure_every: int | None = None
    """Measure the frames after actions N, 2N, ... of each rollout; None: the frames the model imagines
    (all of them, or each chunk's last for a model of one frame per chunk, `actions_per_frame`). Set
    it to compare a model of one frame per action with one of N on the same frames. The horizons
    (h1, h8, h32) are then each the first measured frame at or after it (after actions 5, 10, 35 for N = 5)."""


def evaluate_world_model(wm: Path, data: Path, out: Path, config: WorldModelEvalConfig = WorldModelEvalConfig(),
                         progress: bool = True) -> dict:
    """Measures `wm` on the held-out episodes of `data`; writes the report to `out` and returns it."""
    started = time.perf_counter()
    model = load_world_model(wm, **({} if config.reanchor_every is None else {"reanchor_every": config.reanchor_every}))
    model = placed(model, resolve_device(config.device))
    fraction = heldout_fraction(wm)
    # A model of one frame per chunk is measured on the frames it imagines, not their repeats.
    measured_every = config.measure_every or actions_per_frame(model)
    cameras = model_cameras(model)
    dataset = EpisodeDataset(data, config.camera, cameras or None, keys=config.keys)
    if model_image_size(dataset.camera_shape, model.image_size) != model.image_size:
        raise ValueError(f"{data}: frames are {dataset.camera_shape}, the world model makes {model.image_size}x{model.image_size}")
    dataset = dataset.fitted(model.image_size, frame_fit(Path(wm)))
    _, heldout = split_episodes(dataset.episodes, fraction)
    if config.max_episodes:
        heldout = heldout[: config.max_episodes]
    if not heldout:
        raise ValueError(f"{data} has no held-out episodes for this run (held-out fraction {fraction})")
    grounding = state_source(model, config.robot_state)
    perceptual = PerceptualDistance()
    rows: dict[str, list[np.ndarray]] = defaultdict(list)  # measure -> one (T,) array per rollout
    camera_rows = {camera: defaultdict(list) for camera in cameras}  # each view's, of a multi-view model
    tasks, full_rollout = [], []
    video_dir = out.with_name(out.stem + "_videos")
    generator = torch.Generator().manual_seed(0)  # a generative backend samples: one seed, one report
    for n, index in enumerate(tqdm(heldout, desc="eval-wm", disable=not progress)):
        episode = dataset.load(index)
        frames, actions = torch.from_numpy(episode.observed_frames), torch.from_numpy(episode.actions).float()
        recorded = episode.full_states  # (T + 1, S)
        for start in range(0, len(actions), config.start_every):
            context = frames[max(0, start + 1 - model.context_frames) : start + 1][None]
            states = None if grounding is None else grounding.states(
                recorded[start], episode.actions[start - 1] if start else np.zeros_like(episode.actions[0]),
                episode.info.instruction, episode.actions[None, start:], recorded[None, start + 1 :])
            imagination = rollout(model, context, actions[None, start:], generator, states)
            imagined = imagination.frames[0]  # (T, H, W, 3)
            real = frames[start + 1 :]
            if imagination.disagreement is not None:  # an ensemble, or a user's model that says how far to trust a frame
                rows["disagreement"].append(imagination.disagreement[0].numpy())
            measured = every_nth_frame(len(real), measured_every)
            for name, values in _measure_against_copy(imagined, real, context[0], perceptual, measured).items():
                rows[name].append(values)
            squares = [split_views(x[None], len(cameras)) if cameras else None for x in (imagined, real, context[0])]
            for v, camera in enumerate(cameras):
                for name, values in _measure_against_copy(*(x[v] for x in squares), perceptual, measured).items():
                    camera_rows[camera][name].append(values)
            tasks.append(episode.info.task)
            full_rollout.append(start == 0)
            name = f"{episode.info.task}_{episode.info.behaviour}_{episode.info.seed}"
            if start == 0 and n < config.videos:
                write_side_by_side(video_dir / f"{name}.mp4", real.numpy(), imagined.numpy(), dataset.fps)
            if start == 0 and n < config.gifs:
                # Every 3rd frame of the first 120, at a third of real speed: small files for web pages.
                panels = side_by_side(real[:120:3].numpy(), imagined[:120:3].numpy())
                write_gif(video_dir / f"{name}.gif", panels, fps=dataset.fps // 9, scale=1)
    table = {name: _pad(values) for name, values in rows.items()}  # name -> (N, T_max) with NaN
    report = {**_summary(table, np.array(full_rollout), measured_every), **(disagreement_error(table) if "disagreement" in table else {}), "per_task": {}}
    if cameras:  # the figures above are over the views side by side; these are each view's own
        report["per_camera"] = {camera: _summary({k: _pad(v) for k, v in by_measure.items()}, np.array(full_rollout),
                                                 measured_every)
                                for camera, by_measure in camera_rows.items()}
    for task in sorted(set(tasks)):
        chosen = np.array([t == task for t in tasks])
        report["per_task"][task] = _summary({k: v[chosen] for k, v in table.items()}, np.array(full_rollout)[chosen],
                                            measured_every)
    report["controllability"] = check_controllability(model, dataset, heldout, config.controllability, progress=progress,
                                                      grounding=grounding)
    if grounding is not None:
        report["grounding"] = {"states": grounding.name, "robot_state": str(config.robot_state) if config.robot_state else None}
    report |= {"wm": str(wm), "model": model.spec() if hasattr(model, "spec") else None, "data": str(data),
               "episodes": len(heldout), "rollouts": len(tasks),
               "config": {**asdict(config), "robot_state": None if config.robot_state is None else str(config.robot_state)}, "videos": str(video_dir) if config.videos else None,
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(out, report)
    return report


def state_source(model, robot_state: Path | None) -> StateSource | None:
    """Where a grounded `model`'s states come from (the state model in `robot_state`, else the
    recorded ones); None for a model that is not grounded.

    Raises:
        ValueError: a state model for a model that is not grounded, or one of other states.
    """
    size = grounded_state_dim(model)
    if not size:
        if robot_state is not None:
            raise ValueError(f"--robot-state {robot_state} gives a grounded world model its states; this one is not grounded")
        return None
    if robot_state is None:
        return StateSource()
    models = load_state_models(robot_state)
    if models[0].config.state_dim != size:
        raise ValueError(f"the world model renders at {size}-d states, the state model {robot_state} imagines "
                         f"{models[0].config.state_dim}-d ones")
    return StateSource(models)


PLUGIN_HELDOUT_FRACTION = 0.1
"""The held-out share of scenes measured for a user's own world model (`gymnast.utils.plugins`),
which saves no split of its own: gymnast's default, so its scenes are the ones gymnast's models hold out."""


def heldout_fraction(wm: str | Path) -> float:
    """The held-out share of scenes of a world-model run; of an ensemble, the smallest of its
    members'; of a user's own model, `PLUGIN_HELDOUT_FRACTION`."""
    if is_plugin(wm):
        return PLUGIN_HELDOUT_FRACTION
    if is_ensemble(wm):
        return min(heldout_fraction(member) for member in member_paths(wm))
    return read_json(resolve_checkpoint(wm) / "config.json")["train"]["heldout_fraction"]


def frame_fit(wm: str | Path) -> Fit:
    """How a world-model run fitted its dataset's frames to its image size (`gymnast.data.frames`);
    of an ensemble, its first member's; resize for a user's own model. Runs saved before the
    choice existed read only frames of their own size, which every fit leaves as they are."""
    if is_plugin(wm):
        return "resize"
    if is_ensemble(wm):
        return frame_fit(member_paths(wm)[0])
    return read_json(resolve_checkpoint(wm) / "config.json")["train"].get("fit", "resize")


def disagreement_error(table: dict[str, np.ndarray]) -> dict[str, float | None]:
    """How well an ensemble's disagreement predicts its first member's error, frame by frame.

    The error of a frame is its root mean squared error in [0, 1] units (from its PSNR), the same
    units as the disagreement (a standard deviation). Over every imagined frame of every rollout:
    ``disagreement_error_corr`` (Pearson), ``disagreement_error_spearman`` (rank: any monotone
    relation), and ``disagreement_error_corr_same_step`` (Pearson after removing each horizon's
    mean from both: does disagreement find the bad rollouts, not just the late steps where every
    rollout is worse). None where undefined (constant disagreement, or fewer than 3 frames).

    Args:
        table: measure -> (N, T) per-frame values with NaN padding; needs "disagreement" and "psnr".
    """
    disagreement, error = table["disagreement"], np.sqrt(10.0 ** (-table["psnr"] / 10.0))
    valid = np.isfinite(disagreement) & np.isfinite(error)  # (N, T)
    with np.errstate(all="ignore"):  # all-NaN horizons
        centred = [v - np.nanmean(np.where(valid, v, np.nan), axis=0, keepdims=True) for v in (disagreement, error)]
    return {"disagreement_error_corr": pearson(disagreement[valid], error[valid]),
            "disagreement_error_spearman": pearson(_ranks(disagreement[valid]), _ranks(error[valid])),
            "disagreement_error_corr_same_step": pearson(centred[0][valid], centred[1][valid])}


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks of a 1-d array, ties given their average rank (as Spearman's correlation needs)."""
    ranks = np.empty(len(x))
    ranks[np.argsort(x, kind="stable")] = np.arange(len(x))
    _, tie, counts = np.unique(x, return_inverse=True, return_counts=True)
    return (np.bincount(tie, weights=ranks) / counts)[tie]


def _measure_against_copy(imagined: torch.Tensor, real: torch.Tensor, context: torch.Tensor,
                          perceptual: PerceptualDistance, measured: torch.Tensor) -> dict:
    """`_measure` of the imagined frames, and (as ``copy_last_<measure>``) of repeating the last
    (C, H, W, 3) context frame, the trivial predictor the model must beat: (T,) arrays, NaN at the
    frames not `measured` (T,) bool (the repeats of a model of one frame per chunk, never computed)."""
    spread = {f"{prefix}{name}": np.full(len(measured), np.nan) for prefix in ("", "copy_last_") for name in MEASURES}
    if not measured.any():  # a rollout from near an episode's end, shorter than one chunk
        return spread
    imagined, real = imagined[measured], real[measured]
    copy = _measure(context[-1:].expand_as(real), real, context, perceptual)
    values = _measure(imagined, real, context, perceptual) | {f"copy_last_{name}": v for name, v in copy.items()}
    for name, row in values.items():
        spread[name][measured.numpy()] = row
    return spread


def _measure(imagined: torch.Tensor, real: torch.Tensor, context: torch.Tensor, perceptual: PerceptualDistance) -> dict:
    """Per-frame measures of (T, H, W, 3) uint8 `imagined` against `real`, as (T,) numpy arrays."""
    pred, target = to_unit_float(imagined), to_unit_float(real)  # (T, 3, H, W)
    mask = moving_mask(target, to_unit_float(context[:1]))  # moving w.r.t. the first context frame
    return {"psnr": psnr(pred, target).numpy(), "ssim": ssim(pred, target).numpy(),
            "perceptual": perceptual(pred, target).numpy(), "moving_psnr": masked_psnr(pred, target, mask).numpy()}


def _pad(rows: list[np.ndarray]) -> np.ndarray:
    table = np.full((len(rows), max(len(r) for r in rows)), np.nan)
    for i, row in enumerate(rows):
        table[i, : len(row)] = row
    return table


def _summary(table: dict[str, np.ndarray], full_rollout: np.ndarray, measured_every: int) -> dict:
    """Flat `<measure>_<horizon>` figures (e.g. psnr_h32, copy_last_moving_psnr_h32); with frames
    measured every `measured_every` actions, each horizon at the first measured frame at or after it."""
    summary = {}
    for name, values in table.items():
        by_horizon = summarize_horizons(values, measured_every=measured_every)
        by_horizon["full"] = summarize_horizons(values[full_rollout])["full"]
        summary |= {f"{name}_{h}": (None if v is None else round(float(v), 4)) for h, v in by_horizon.items()}
    return dict(sorted(summary.items()))


def format_report(report: dict) -> str:
    """A short table of the headline figures, model against repeat-last-frame."""
    lines = ["world model / repeat last frame", f"{'measure':<14}" + "".join(f"{h:>16}" for h in ("h1", "h8", "h32", "full"))]
    for name in MEASURES:
        digits = 4 if name == "perceptual" else 2  # perceptual distances are small numbers
        cells = []
        for h in ("h1", "h8", "h32", "full"):
            model, copy = report.get(f"{name}_{h}"), report.get(f"copy_last_{name}_{h}")
            cells.append("-" if model is None or copy is None else f"{model:.{digits}f}/{copy:.{digits}f}")
        lines.append(f"{name:<14}" + "".join(f"{c:>16}" for c in cells))
    for camera, figures in report.get("per_camera", {}).items():
        def pair(name: str, h: str) -> str:
            model, copy = figures.get(f"{name}_{h}"), figures.get(f"copy_last_{name}_{h}")
            return "-" if model is None or copy is None else f"{model:.2f}/{copy:.2f}"

        cells = ", ".join(f"{name} {h} {pair(name, h)}" for name, h in (("psnr", "h32"), ("moving_psnr", "h32"), ("psnr", "full")))
        lines.append(f"camera {camera}: {cells} (model/repeat last frame)")
    if "disagreement_error_corr" in report:
        lines.append(f"ensemble disagreement: h1 {report['disagreement_h1']}, h32 {report['disagreement_h32']}; "
                     f"correlation with the first member's error {report['disagreement_error_corr']} "
                     f"(rank {report['disagreement_error_spearman']}, same step {report['disagreement_error_corr_same_step']})")
    control = report.get("controllability", {})
    if control:
        lines.append(f"controllability: matched {control['matched_psnr']:.2f} dB vs mismatched {control['mismatched_psnr']:.2f} dB; "
                     f"identified {control['identification_accuracy']:.0%} of action sequences")
    return "\n".join(lines)
