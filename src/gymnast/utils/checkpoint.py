"""Checkpoints: ``RUN/checkpoints/<step:06d>/`` written whole or not at all, with ``last`` pointing
at the newest.

A checkpoint holds the weights (safetensors: no code runs on load), the resolved configuration
(JSON), the optimizer and random-generator states (tensors only, loaded with
``weights_only=True``) and the trainer's own counters (JSON), so ``--resume`` continues exactly.
It is written into a temporary directory that is renamed into place, then ``last`` is replaced
atomically: a crash leaves the previous checkpoint as the newest, never a half-written one.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Sequence
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file
from torch import nn

from gymnast.utils.atomic import atomic_directory, read_json, write_bytes, write_json
from gymnast.utils.metrics import MetricsLog
from gymnast.utils.trackers import open_trackers

logger = logging.getLogger(__name__)

LAST = "last"
OPTIMIZER_FILE = "optimizer.pt"


def save_checkpoint(
    run: Path,
    step: int,
    model: nn.Module,
    config: dict,
    optimizer: torch.optim.Optimizer | None = None,
    rng: dict[str, torch.Tensor] | None = None,
    trainer: dict | None = None,
    extra: dict[str, dict] | None = None,
) -> Path:
    """Writes checkpoint `step` of `run` and points ``last`` at it; returns its directory.

    `extra` names further state dicts saved beside the model (``NAME.pt``; `load_extra` reads one),
    such as a second network a trainer fits with its own optimizer.
    """
    final = checkpoint_at(run, step)
    root = final.parent
    root.mkdir(parents=True, exist_ok=True)
    # A rerun of the same step (e.g. after a resume) replaces it.
    with atomic_directory(final, replace=True) as staging:
        # Weights are saved from the host, so a checkpoint written on a GPU loads on any machine.
        save_file({k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}, staging / "model.safetensors")
        (staging / "config.json").write_text(json.dumps(config, indent=2, default=str))
        (staging / "trainer.json").write_text(json.dumps({"step": step, **(trainer or {})}, indent=2))
        if optimizer is not None:
            torch.save(optimizer.state_dict(), staging / OPTIMIZER_FILE)
        if rng is not None:
            torch.save(rng, staging / "rng.pt")
        for name, state in (extra or {}).items():
            torch.save(state, staging / f"{name}.pt")
    write_bytes(root / LAST, final.name.encode())
    return final


def checkpoint_at(run: Path, step: int) -> Path:
    """Where `run` keeps (or would keep) its checkpoint of `step`."""
    return Path(run) / "checkpoints" / f"{step:06d}"


def has_checkpoint(run: Path) -> bool:
    """Whether `run` has saved a checkpoint (a trainer given it resumes rather than starts)."""
    return (Path(run) / "checkpoints" / LAST).exists()


def resolve_checkpoint(path: Path) -> Path:
    """A checkpoint directory, given it or a run directory (whose ``last`` checkpoint is used)."""
    path = Path(path)
    if (path / "model.safetensors").exists():
        return path
    last = path / "checkpoints" / LAST
    if last.exists():
        checkpoint = path / "checkpoints" / last.read_text().strip()
        if (checkpoint / "model.safetensors").exists():
            return checkpoint
        raise FileNotFoundError(f"{last} points at {checkpoint}, which has no model.safetensors")
    raise FileNotFoundError(f"no checkpoint in {path} (expected {path}/checkpoints/{LAST} or {path}/model.safetensors)")


def load_checkpoint(checkpoint: Path, model: nn.Module, optimizer: torch.optim.Optimizer | None = None) -> tuple[dict, dict]:
    """Restores weights (and optimizer state) in place; returns (trainer state, rng tensors)."""
    model.load_state_dict(load_file(checkpoint / "model.safetensors"))
    if optimizer is not None:
        # Read onto the host; the optimizer moves its state to its parameters' device.
        state = checkpoint / OPTIMIZER_FILE
        if not state.is_file():
            raise FileNotFoundError(f"{checkpoint} has no {OPTIMIZER_FILE}: the run was exported without its optimizer "
                                    "state (gymnast export), so its weights load but its training cannot go on exactly; "
                                    "start a new run from it instead")
        optimizer.load_state_dict(torch.load(state, weights_only=True, map_location="cpu"))
    rng = torch.load(checkpoint / "rng.pt", weights_only=True, map_location="cpu") if (checkpoint / "rng.pt").exists() else {}
    return read_json(checkpoint / "trainer.json"), rng


def load_extra(checkpoint: Path, name: str) -> dict:
    """The state dict `save_checkpoint` saved under `name` in `checkpoint`, read onto the host.

    Raises:
        FileNotFoundError: the checkpoint has none (a run saved without it).
    """
    path = Path(checkpoint) / f"{name}.pt"
    if not path.exists():
        raise FileNotFoundError(f"{checkpoint} has no {path.name}: it was saved by a run without a {name}")
    return torch.load(path, weights_only=True, map_location="cpu")


def write_run_config(run: Path, config: dict) -> None:
    """Saves the resolved configuration of a run at its root (every checkpoint has it too)."""
    write_json(Path(run) / "config.json", config)


def save_training(run: Path, step: int, model: nn.Module, config: dict, optimizer: torch.optim.Optimizer,
                  schedule: torch.optim.lr_scheduler.LRScheduler, sampler: torch.Generator) -> Path:
    """A trainer's checkpoint: weights, config, optimizer, learning-rate schedule and batch sampler."""
    return save_checkpoint(run, step, model, config, optimizer, {"sampler": sampler.get_state()},
                           {"schedule": schedule.state_dict()})


def resume_training(run: Path, model: nn.Module, optimizer: torch.optim.Optimizer,
                    schedule: torch.optim.lr_scheduler.LRScheduler, sampler: torch.Generator) -> int:
    """Restores what `save_training` wrote last into the live objects; returns the step to go on from."""
    trainer, rng = load_checkpoint(resolve_checkpoint(run), model, optimizer)
    schedule.load_state_dict(trainer["schedule"])
    sampler.set_state(rng["sampler"])
    return trainer["step"]


def begin_training(run: Path, resolved: dict, model: nn.Module, optimizer: torch.optim.Optimizer,
                   schedule: torch.optim.lr_scheduler.LRScheduler, sampler: torch.Generator, resume: bool,
                   writes: bool = True, tracker: Sequence[str] = (), kind: str = "") -> tuple[int, MetricsLog | None]:
    """Where a trainer starts: the step to go on from (restored from the run's last checkpoint on
    `resume`, else 0) and, on the process that `writes` the run, its metrics log, with the resolved
    settings saved at the run's root and logged to the trackers named in `tracker` (a run of `kind`,
    `gymnast.utils.trackers.open_trackers`). The other processes of a distributed run get no log."""
    start = resume_training(run, model, optimizer, schedule, sampler) if resume else 0
    if resume:
        logger.info("resumed %s at step %d", run, start)
    if not writes:
        return start, None
    write_run_config(run, resolved)
    resume_step = start if resume else None
    trackers = open_trackers(tracker, run, resume_step, kind, resolved)
    return start, MetricsLog(run, resume_step=resume_step, tracker=trackers)


def load_model(run: Path, build: Callable[[dict], nn.Module]) -> nn.Module:
    """The newest checkpoint of `run` (or a checkpoint directory): `build(saved model spec)`, its
    weights loaded, in eval mode.

    Raises:
        FileNotFoundError: no checkpoint there.
    """
    path = resolve_checkpoint(Path(run))
    model = build(read_json(path / "config.json").get("model", {}))
    model.load_state_dict(load_file(path / "model.safetensors"))
    return model.eval()


