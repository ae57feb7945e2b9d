"""`gymnast` commands that train and measure world models: the video model, the state model, ensembles."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Annotated, Literal

import tyro

from gymnast.cli.flags import GPUPreset, KeyFlags, feature_keys, key_overrides
from gymnast.cli.settings import resolve, saved_inputs
from gymnast.config import CameraNames
from gymnast.data.frames import Fit
from gymnast.utils.trackers import TrackerNames

logger = logging.getLogger(__name__)


def train_wm(
    out: Path,
    data: Path | None = None,
    backend: Literal["embedded", "flow"] | None = None,
    preset: GPUPreset = "full",
    resume: bool = False,
    device: str | None = None,
    steps: int | None = None,
    seed: int | None = None,
    future: int | None = None,
    moving_weight: float | None = None,
    action_dropout: float | None = None,
    actions_per_frame: int | None = None,
    grounded: bool | None = None,
    state_noise: float | None = None,
    init: Path | None = None,
    extra_data: tuple[Path, ...] = (),
    camera: str | None = None,
    cameras: CameraNames = (),
    fit: Fit | None = None,
    tracker: TrackerNames | None = None,
    heldout_fraction: float | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Train a world model on every episode of a dataset (held-out scenes excepted).

    Args:
        out: run directory: checkpoints, metrics.jsonl, config.json, videos/.
        data: dataset directory (from `gymnast collect`); with --resume, the run's own.
        backend: embedded (deterministic; the default) or flow (generative: latent flow matching, one sampled
            frame per action); with --resume, the run's own.
        preset: debug (seconds), demo (minutes), full (under an hour on 2 cores) or gpu (a larger model
            for one GPU; docs/gpu.md).
        resume: continue the run in OUT from its last checkpoint, with the settings and data saved there.
        device: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N.
        steps: override the preset's optimizer steps.
        seed: override the seed.
        future: actions per training clip, imagined open-loop and backpropagated through (the preset's: 32
            for the embedded backend; 1 trains on one-step predictions alone).
        moving_weight: extra loss weight of moving pixels, normalised (0 = plain mean squared error).
        action_dropout: share of training steps whose action is hidden, so that the model can be
            imagined with action guidance (`guidance` in its config.json; docs/world_model.md).
        actions_per_frame: imagine one frame per chunk of this many actions, one latent step each (the
            policy's action chunk, e.g. 5; embedded backend; 1 = a frame per action). Fine-tunes from a
            model of one frame per action.
        grounded: render every frame at the episode's recorded state (embedded backend): the model
            then imagines beside a state model that gives it the states (`gymnast rl --robot-state`).
        state_noise: with --grounded, noise on the recorded states in training, in units of their spread
            (a state model's imagined states are that far off).
        init: fine-tune: start from the weights of this world-model run or checkpoint (same model spec).
        extra_data: more dataset directories to train on (same image size), split by the same scene hash.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        cameras: several dataset cameras to imagine side by side, the primary first (e.g. front,gripper):
            one model learns every camera's view; saved with the model, so rl starts it from the views a
            policy of those cameras sees. Default: --camera alone.
        fit: how frames that are not the model's square size are fitted: resize (squash the whole
            frame) or crop (the central square); saved with the run.
        tracker: where the run also logs its settings, metrics and held-out videos: none, or any of tensorboard and
            wandb, comma-separated (wandb: the [wandb] extra; WANDB_MODE=offline keeps it on disk);
            default: none; --resume may change it.
        heldout_fraction: share of scenes kept out of training for eval-wm (the preset's: 0.1); a dataset
            of a few episodes, where 0.1 holds out none, needs more (the warning says how much).
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.world_model.train import saved_train_config, train_world_model, wm_preset

    config, inputs = resolve(
        "train-wm", out, resume, wm_preset(preset, backend or "embedded"), inputs={"data": data}, required=("data",),
        overrides={"backend": backend, "device": device, "steps": steps, "seed": seed, "future": future,
                   "moving_weight": moving_weight,
                   f"{'flow' if backend == 'flow' else 'model'}.action_dropout": action_dropout,
                   "model.actions_per_frame": actions_per_frame,
                   "grounded": grounded, "state_noise": state_noise, "init": init, "extra_data": extra_data or None, "camera": camera, "cameras": cameras or None, "fit": fit,
                   "tracker": tracker, "heldout_fraction": heldout_fraction, **key_overrides(keys)},
        saved=lambda: (saved_train_config(out), saved_inputs(out, "data")))
    if not resume and config.heldout_fraction:
        hint = _heldout_hint(inputs["data"], config.heldout_fraction, config.camera, config.keys)
        if hint:
            logger.warning("%s: eval-wm will have nothing to measure", hint)
    checkpoint = train_world_model(inputs["data"], out, config, resume=resume)
    print(f"world model: {checkpoint}")


def train_state(
    out: Path,
    data: Path | None = None,
    resume: bool = False,
    steps: int = 4000,
    unroll: int = 16,
    seed: int = 0,
    ridge: float = 1e-4,
    last_action: bool = True,
    extra_data: tuple[Path, ...] = (),
    init: Path | None = None,
    tracker: TrackerNames = (),
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Train the grounded state model on a dataset's recorded states, rewards and success flags: the
    state under the actions, and a reward head read off it (`--reward state:OUT`); writes
    OUT/eval.json, its open-loop errors on the held-out scenes.

    Args:
        out: run directory: checkpoints, metrics.jsonl, config.json, eval.json.
        data: dataset directory (from `gymnast collect`, or a LeRobot dataset with observation.state);
            with --resume, the run's own.
        resume: continue the run in OUT from its last checkpoint, with the settings and data saved there.
        steps: optimizer steps.
        unroll: steps imagined open loop per training window.
        seed: seed of the weights and of the windows drawn.
        ridge: start the dynamics' linear path at the least-squares fit of the recorded steps with this
            ridge penalty (0: at zero).
        last_action: condition each step on the action before it too.
        extra_data: more datasets to train on, e.g. the policy's own rollouts (`gymnast collect --policy`).
        init: fine-tune: start from the weights of this state-model run or checkpoint (its architecture
            and normalisation kept), e.g. on the policy's newest rollouts with --extra-data.
        tracker: where the run also logs its settings and metrics: none, or any of tensorboard and
            wandb, comma-separated (wandb: the [wandb] extra); with --resume, replaces the run's.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.utils.settings import from_json, saved_settings
    from gymnast.world_model.train_state import StateTrainConfig, train_state_model

    if resume:
        config, data = from_json(StateTrainConfig, saved_settings(out, "train")), Path(saved_settings(out)["data"])
        config = dataclasses.replace(config, tracker=tracker) if tracker else config
    elif data is None:
        raise ValueError("train-state needs --data (or --resume to continue the run in --out)")
    else:
        config = StateTrainConfig(steps=steps, unroll=unroll, seed=seed, ridge=ridge, last_action=last_action,
                                  extra_data=extra_data, keys=feature_keys(keys), init=init, tracker=tracker)
    checkpoint = train_state_model(data, out, config, resume=resume)
    print(f"state model: {checkpoint}; held-out errors: {out / 'eval.json'}")


def eval_wm(
    wm: Path,
    data: Path,
    out: Path,
    max_episodes: int = 0,
    videos: int = 6,
    gifs: int = 0,
    control_scenes: int = 10,
    reanchor_every: int | None = None,
    camera: str | None = None,
    device: str = "auto",
    robot_state: Path | None = None,
    measure_every: int | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Measure a world model's open-loop fidelity and controllability on held-out episodes.

    Args:
        wm: world-model run (or checkpoint) directory, or an ensemble; or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help) (measured on the
            scenes gymnast's own models hold out).
        data: dataset directory; its episodes from held-out scenes are used.
        out: report JSON; side-by-side videos go to <out stem>_videos/.
        max_episodes: evaluate at most this many held-out episodes (0 = all).
        videos: side-by-side videos (real | imagined | difference) to write.
        gifs: also write the first GIFS of them as small looping GIFs.
        control_scenes: held-out scenes for the controllability check (0 skips it).
        reanchor_every: override how often a long rollout re-encodes its own frames (0 = never).
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        device: where the world model imagines: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N.
        robot_state: for a grounded world model (train-wm --grounded), the state model (or ensemble) run whose
            imagined states it renders at, from each rollout's real start; default: the recorded states.
        measure_every: measure the frames after actions N, 2N, ... of each rollout (default: those the model
            imagines: every frame, or each chunk's last for a model of one frame per chunk); e.g. 5 to
            compare a model of one frame per action with one per 5-action chunk on the same frames.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state).
    """
    from gymnast.world_model.controllability import ControllabilityConfig
    from gymnast.world_model.evaluate import WorldModelEvalConfig, evaluate_world_model, format_report

    config = WorldModelEvalConfig(max_episodes=max_episodes, videos=videos, gifs=gifs,
                                  controllability=ControllabilityConfig(scenes=control_scenes), reanchor_every=reanchor_every,
                                  camera=camera, device=device, keys=feature_keys(keys), robot_state=robot_state,
                                  measure_every=measure_every)
    from gymnast.world_model.evaluate import heldout_fraction

    hint = _heldout_hint(data, heldout_fraction(wm), camera, feature_keys(keys))
    if hint:
        raise ValueError(f"{hint}; or evaluate on other episodes of the robot")
    report = evaluate_world_model(wm, data, out, config)
    print(format_report(report))
    print(f"report: {out}")


def object_fidelity(
    wm: Path,
    data: Path,
    out: Path,
    extra_data: tuple[Path, ...] = (),
    tasks: str = "pick-place-v3,push-v3,peg-insert-side-v3",
    steps: int = 3000,
) -> None:
    """Object-level fidelity: train a position probe on real frames, then measure how far the object the
    world model imagines (open-loop, held-out episodes) is from the real one at steps 1, 8, 16, 32, 64, 128.

    Args:
        wm: world-model run (or checkpoint) directory; its held-out scenes are measured; or your own:
            python:MODULE:FACTORY[@ARG] or plugin:NAME[@ARG] (gymnast check-wm --help).
        data: dataset directory.
        out: report JSON (per task and step: centimetres, counts, probe floor, settings, seconds).
        extra_data: more datasets (same image size) to train the probe on and measure.
        tasks: tasks with a small object, comma-separated.
        steps: optimizer steps of the probe.
    """
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.world_model.object_probe import ObjectProbeConfig, format_object_table, measure_object_fidelity

    config = ObjectProbeConfig(tasks=resolve_tasks(tasks), steps=steps)
    report = measure_object_fidelity(wm, data, out, extra_data, config)
    print(format_object_table(report))
    print(f"report: {out}")


def make_ensemble(members: tuple[Path, ...], out: Path) -> None:
    """Make an ensemble of world-model runs, or of state-model runs: OUT/ensemble.json lists them
    (relative to OUT). An ensemble of world models works wherever a world-model run does (--wm OUT;
    eval-wm also reports where the members disagree); one of state models wherever a state-model run
    does (--reward state:OUT: the members' mean reward, a success only where all predict it).

    Args:
        members: two or more world-model runs (the first one's frames are the ensemble's), or two or
            more `gymnast train-state` runs (or checkpoints).
        out: ensemble directory (created if missing).
    """
    from gymnast.world_model.ensemble import write_ensemble
    from gymnast.world_model.state_model import is_state_model, write_state_ensemble

    if any(is_state_model(member) for member in members):
        print(f"ensemble of {len(write_state_ensemble(out, members))} state models: {out}")
        return
    model = write_ensemble(out, members)
    print(f"ensemble of {len(model.members)} world models: {out}")


def check_wm(wm: str, batch: int = 2, actions: int = 5, device: str = "cpu", seed: int = 0) -> None:
    """Check a world model against the WorldModel contract gymnast relies on, and name each breach with
    what to change: frames uint8 of the declared size, one per action; a state that step() leaves as
    it was (rollouts branch from it); every random draw from the generator given (reproducible); the
    declared action width; a batch's rows the same as batches of one; a context shorter than
    context_frames accepted; and the optional parts a model declares (an ensemble's disagreement,
    offload() and onload()). Exits with status 1 when it finds a breach.

    Args:
        wm: the world model: RUN (a world-model run or checkpoint directory, or an ensemble directory),
            python:MODULE:FACTORY[@ARG] (your own: FACTORY(ARG) returns it) or plugin:NAME[@ARG] (a
            factory an installed package registers in the entry-point group gymnast.world_models).
        batch: rollouts per batched call (at least 2).
        actions: actions per step() call.
        device: where the model runs: cpu, auto, cuda or cuda:N.
        seed: of the synthetic frames and actions, and of the generators.
    """
    from gymnast.utils.device import resolve_device
    from gymnast.utils.plugins import format_breaches
    from gymnast.world_model.base import load_world_model, placed
    from gymnast.world_model.check import check_world_model

    model = placed(load_world_model(wm), resolve_device(device))
    breaches = check_world_model(model, batch=batch, actions=actions, seed=seed)
    print(format_breaches(f"world model {wm}", breaches))
    if breaches:
        raise SystemExit(1)


def _heldout_hint(data: Path, fraction: float, camera: str | None, keys) -> str | None:
    """Where `fraction` holds out no scene of `data`, a message saying so and which fraction would hold
    out one (`--heldout-fraction F` of train-wm); None where it holds out some."""
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.world_model.data import is_heldout, split_episodes, usable_episodes

    infos = EpisodeDataset(data, camera, keys=keys).episodes
    if split_episodes(infos, fraction)[1]:
        return None
    usable = usable_episodes(infos)
    message = f"{data} has no held-out episodes at held-out fraction {fraction} (of its {len(usable)} scenes)"
    for percent in range(1, 100):  # the scene hash is fixed: the smallest share that holds one out
        held = [i for i in usable if is_heldout(infos[i], percent / 100)]
        if held and len(held) < len(usable):
            return f"{message}; train-wm --heldout-fraction {percent / 100:g} holds out episodes {held}"
    return message
