"""Experiment trackers: where a run's settings, metrics, videos and plots go besides RUN/metrics.jsonl.

Legend: T frames, H/W image height/width; videos are (T, H, W, 3) uint8 and images (H, W, 3) uint8.

``--tracker`` names any of `TRACKERS`, several at once (``tensorboard,wandb``), or ``none``:

- ``tensorboard``: event files in RUN/tensorboard/ (``tensorboard --logdir RUN``); videos as
  animated GIFs in the images tab (TensorBoard's own video summary would need moviepy), encoded
  in a background thread while the run goes on.
- ``wandb``: a Weights & Biases run (the ``wandb`` extra: ``pip install 'world-gymnast[wandb]'``),
  its files in RUN/wandb/. W&B reads its own environment: ``WANDB_MODE=offline`` keeps everything on
  disk (``wandb sync`` uploads it later), ``WANDB_PROJECT`` names the project (default ``gymnast``).

RUN/metrics.jsonl stays the record (`gymnast.utils.metrics.MetricsLog` writes it and forwards to
the trackers), so a tracker may fail to start without a run losing its figures: asking for one
that cannot start is said before training, naming what to install. A resumed run continues its
trackers: TensorBoard drops the events past the checkpoint (as metrics.jsonl drops its lines), and
W&B continues the same run (its id is kept in RUN/wandb/run_id), ignoring steps it already has.
"""

from __future__ import annotations

import atexit
import concurrent.futures
import importlib.util
import io
import json
import os
import secrets
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Annotated, Protocol

import numpy as np
import tyro
from PIL import Image

from gymnast.utils.atomic import write_bytes

TRACKERS = ("tensorboard", "wandb")
"""The trackers a run can log to (``none``: only RUN/metrics.jsonl)."""

TrackerNames = Annotated[
    tuple[str, ...],
    tyro.constructors.PrimitiveConstructorSpec(
        nargs=1,
        metavar="{none,tensorboard,wandb}[,...]",
        instance_from_str=lambda args: parse_trackers(args[0]),
        is_instance=lambda value: isinstance(value, tuple),
        str_from_instance=lambda value: [",".join(value) or "none"],
    ),
]
"""Tracker names written on the command line as ``tensorboard,wandb`` (or ``none``)."""

GIF_FRAMES = 64  # a tracker's video keeps at most this many frames (evenly spaced): a preview, not the record
_GIF_MS = 100  # shown at 10 frames a second


def parse_trackers(text: str) -> tuple[str, ...]:
    """The tracker names in ``tensorboard,wandb`` (``none`` or nothing: none), checked."""
    names = tuple(name.strip() for name in text.split(",") if name.strip() and name.strip() != "none")
    return check_trackers(names)


def check_trackers(names: Sequence[str]) -> tuple[str, ...]:
    """`names` as a tuple, each one of `TRACKERS` and none twice.

    Raises:
        ValueError: an unknown or repeated name.
    """
    unknown = [name for name in names if name not in TRACKERS]
    if unknown or len(set(names)) < len(names):
        raise ValueError(f"--tracker takes none or any of {', '.join(TRACKERS)}, comma-separated, each once; "
                         f"got {','.join(names)}")
    return tuple(names)


def require_trackers(names: Sequence[str]) -> None:
    """Raises ImportError, naming the extra to install, where a tracker in `names` is not installed;
    called before a run starts rather than after its first step."""
    if "wandb" in names and importlib.util.find_spec("wandb") is None:
        raise ImportError("--tracker wandb needs Weights & Biases, which is not installed: "
                          "pip install 'world-gymnast[wandb]' (or leave wandb out of --tracker)")


class Tracker(Protocol):
    """Where a run's settings, metrics, videos and images are logged besides RUN/metrics.jsonl."""

    def log_config(self, config: Mapping[str, object]) -> None:
        """The run's resolved settings (what RUN/config.json holds)."""

    def log_metrics(self, step: int, values: Mapping[str, float]) -> None:
        """Scalars of one step, named with the fixed prefixes (train/, eval/, time/ ...)."""

    def log_video(self, key: str, step: int, video: Path | np.ndarray, fps: int = 10) -> None:
        """A video: an mp4 file or (T, H, W, 3) uint8 frames."""

    def log_image(self, key: str, step: int, image: Path | np.ndarray) -> None:
        """An image (a plot): a PNG file or (H, W, 3) uint8 pixels."""

    def close(self) -> None:
        """Flush and release; the tracker takes nothing more."""


class Trackers:
    """The trackers of one run, each logged to in turn (a `Tracker` itself; none: does nothing)."""

    def __init__(self, trackers: Sequence[Tracker] = ()) -> None:
        self.trackers = list(trackers)
        if self.trackers:  # a run that stops on an error still flushes what it logged
            atexit.register(self.close)

    def log_config(self, config: Mapping[str, object]) -> None:
        for tracker in self.trackers:
            tracker.log_config(config)

    def log_metrics(self, step: int, values: Mapping[str, float]) -> None:
        for tracker in self.trackers:
            tracker.log_metrics(step, values)

    def log_video(self, key: str, step: int, video: Path | np.ndarray, fps: int = 10) -> None:
        for tracker in self.trackers:
            tracker.log_video(key, step, video, fps)

    def log_image(self, key: str, step: int, image: Path | np.ndarray) -> None:
        for tracker in self.trackers:
            tracker.log_image(key, step, image)

    def close(self) -> None:
        trackers, self.trackers = self.trackers, []
        for tracker in trackers:
            tracker.close()
        atexit.unregister(self.close)


def open_trackers(names: Sequence[str], run: Path, resume_step: int | None = None, kind: str = "",
                  config: Mapping[str, object] | None = None) -> Trackers:
    """The trackers `names` of the run in `run`, its settings `config` logged.

    Args:
        names: tracker names (`TRACKERS`); empty: none.
        run: the run directory.
        resume_step: when resuming from a checkpoint at this step, the step to continue after; None
            for a new run (a tracker's earlier files there are replaced).
        kind: what the run is (sft, train-wm, rl ...), a W&B run's job type.
        config: the run's resolved settings, logged once.

    Raises:
        ValueError, ImportError: see `check_trackers` and `require_trackers`.
    """
    names = check_trackers(names)
    require_trackers(names)
    opened = Trackers([TensorBoardTracker(run, resume_step) if name == "tensorboard" else
                       WandbTracker(run, resume_step, kind) for name in names])
    if config is not None:
        opened.log_config(config)
    return opened


class TensorBoardTracker:
    """TensorBoard event files in RUN/tensorboard/.

    A video's GIF is encoded in a background thread (decoding and encoding an RL group video took
    most of the trackers' time in a debug step, benchmarks/tracker_overhead.py) and written once a
    later step is logged, or at `close`: TensorBoard reads a step below one already written as a
    restarted run and drops what came after it, so events go out in the order of their steps.
    """

    def __init__(self, run: Path, resume_step: int | None = None) -> None:
        from torch.utils.tensorboard import SummaryWriter

        # purge_step drops the events past the resumed checkpoint (from that step on), as metrics.jsonl does.
        purge = None if resume_step is None else resume_step + 1
        self.writer = SummaryWriter(str(Path(run) / "tensorboard"), purge_step=purge)
        self.encoder = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="tensorboard-gif")
        self.pending: list[tuple[int, concurrent.futures.Future]] = []  # (step, its video's summary), in order

    def log_config(self, config: Mapping[str, object]) -> None:
        text = json.dumps(config, indent=2, default=str)
        self.writer.add_text("config", "\n".join(f"    {line}" for line in text.splitlines()))  # markdown: code

    def log_metrics(self, step: int, values: Mapping[str, float]) -> None:
        self._write_videos(before=step)
        for key, value in values.items():
            self.writer.add_scalar(key, value, step)

    def log_video(self, key: str, step: int, video: Path | np.ndarray, fps: int = 10) -> None:
        self._write_videos(before=step)
        self.pending.append((step, self.encoder.submit(_gif_summary, key, video)))

    def log_image(self, key: str, step: int, image: Path | np.ndarray) -> None:
        self._write_videos(before=step)
        self.writer.add_image(key, _pixels(image), step, dataformats="HWC")

    def close(self) -> None:
        self._write_videos()
        self.encoder.shutdown()
        self.writer.close()

    def _write_videos(self, before: int | None = None) -> None:
        """Writes the encoded videos of the steps before `before` (all of them without it)."""
        while self.pending and (before is None or self.pending[0][0] < before):
            step, summary = self.pending.pop(0)
            self.writer.file_writer.add_summary(summary.result(), step)


class WandbTracker:
    """A Weights & Biases run, its files in RUN/wandb/ (the ``wandb`` extra)."""

    def __init__(self, run: Path, resume_step: int | None = None, kind: str = "") -> None:
        import wandb

        self.folder = folder = Path(run) / "wandb"
        folder.mkdir(parents=True, exist_ok=True)
        saved = folder / "run_id"
        # A resumed run goes on in the same W&B run; a new one gets a new id.
        run_id = saved.read_text().strip() if resume_step is not None and saved.is_file() else secrets.token_hex(4)
        write_bytes(saved, run_id.encode())
        self.run = wandb.init(dir=str(run), id=run_id, resume="allow", name=Path(run).resolve().name,
                              group=Path(run).resolve().parent.name, job_type=kind or None, reinit="create_new",
                              project=os.environ.get("WANDB_PROJECT") or "gymnast")

    def log_config(self, config: Mapping[str, object]) -> None:
        self.run.config.update(json.loads(json.dumps(config, default=str)), allow_val_change=True)

    def log_metrics(self, step: int, values: Mapping[str, float]) -> None:
        self.run.log(dict(values), step=step)

    def log_video(self, key: str, step: int, video: Path | np.ndarray, fps: int = 10) -> None:
        import wandb

        if not isinstance(video, Path):  # W&B encodes frames only with moviepy: it gets a GIF file instead
            path = self.folder / "previews" / f"{key.replace('/', '_')}_{step:06d}.gif"
            path.parent.mkdir(exist_ok=True)
            write_bytes(path, gif_bytes(preview_frames(video)))
            video = path
        self.run.log({key: wandb.Video(str(video))}, step=step)

    def log_image(self, key: str, step: int, image: Path | np.ndarray) -> None:
        import wandb

        self.run.log({key: wandb.Image(_pixels(image))}, step=step)

    def close(self) -> None:
        self.run.finish()


def _gif_summary(key: str, video: Path | np.ndarray):
    """A TensorBoard image summary holding `video` as an animated GIF."""
    from tensorboard.compat.proto.summary_pb2 import Summary

    frames = preview_frames(video)
    image = Summary.Image(height=frames.shape[1], width=frames.shape[2], colorspace=3,
                          encoded_image_string=gif_bytes(frames))
    return Summary(value=[Summary.Value(tag=key, image=image)])


def preview_frames(video: Path | np.ndarray) -> np.ndarray:
    """(T', H, W, 3) uint8: at most `GIF_FRAMES` evenly spaced frames of an mp4 or of (T, H, W, 3) frames."""
    if isinstance(video, Path):
        from gymnast.utils.video import decode_video

        video = decode_video(video)
    frames = np.asarray(video)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"a video to log must be (T, H, W, 3) uint8 frames, got {frames.shape} {frames.dtype}")
    return frames[np.linspace(0, len(frames) - 1, min(len(frames), GIF_FRAMES)).round().astype(int)]


def gif_bytes(frames: np.ndarray) -> bytes:
    """An animated GIF of (T, H, W, 3) uint8 frames, looping."""
    # Each frame's own palette by the fast octree: Pillow's default (median cut, dithered) took 2 s
    # for 11 frames of an RL group video, 70x as long, to a GIF of the same size.
    images = [Image.fromarray(frame).quantize(256, method=Image.Quantize.FASTOCTREE) for frame in frames]
    buffer = io.BytesIO()
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:], duration=_GIF_MS, loop=0)
    return buffer.getvalue()


def _pixels(image: Path | np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 pixels of an image file or array."""
    if isinstance(image, Path):
        with Image.open(image) as opened:
            return np.asarray(opened.convert("RGB"))
    return np.asarray(image)
