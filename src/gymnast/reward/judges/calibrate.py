"""A trained per-frame judge calibrated on labelled real videos it never saw.

Training chooses a judge's threshold on its validation scenes, a tenth of its data: a few dozen
episodes, whose few negatives cannot place a threshold within the one or two cases that decide a
false-success rate of a few percent (docs/rewards.md, "Stopping earlier"). Calibration takes more
episodes recorded apart (new scenes: `gymnast collect --first-seed`), judges their cases as the
held-out ones are judged (whole episodes and successes cut short, `judge_cases`), and chooses,
among the run's checkpoints and hold rules asked for, the threshold that passes the most successes
while calling at most `max_fpr` of the failures successes. The chosen judge is written as a judge
run of its own, loadable wherever a judge run is, with the run's held-out figures measured again
under it (`metrics.json`), so the scenes that choose and the scenes that measure stay apart.

Legend: T frames of a video, N cases.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from gymnast.reward.judges.frames import FrameJudge, held_probability
from gymnast.reward.judges.measure import evaluate_judge, roc_readout, threshold_at_fpr
from gymnast.reward.judges.train import judge_datasets, load_judge, run_scene_videos, saved_judge_config
from gymnast.reward.judges.videos import Video, judge_cases, load_videos
from gymnast.utils.atomic import atomic_directory, read_json, write_json
from gymnast.utils.checkpoint import checkpoint_at, resolve_checkpoint, save_checkpoint, write_run_config


@dataclass(frozen=True)
class CalibrationConfig:
    """What calibration may choose among, and the false-success rate it holds to."""

    max_fpr: float = 0.02
    """The share of the calibration failures the chosen threshold may call successes."""
    hold_steps: tuple[int, ...] = ()
    """Hold rules to try (`JudgeConfig.hold_steps`); empty: the judge's own."""
    checkpoints: tuple[int, ...] = ()
    """Steps of the run's earlier checkpoints to try besides its newest (stopping earlier)."""

    def __post_init__(self) -> None:
        if not 0 <= self.max_fpr < 1:
            raise ValueError(f"CalibrationConfig.max_fpr must be in [0, 1), got {self.max_fpr}")
        if any(steps < 1 for steps in self.hold_steps):
            raise ValueError(f"CalibrationConfig.hold_steps must be at least 1, got {self.hold_steps}")


def calibrate_judge(run: Path, data: Sequence[Path], out: Path, config: CalibrationConfig = CalibrationConfig(),
                    progress: bool = True) -> dict:
    """Chooses `run`'s checkpoint, hold rule and threshold on the real episodes of `data`, writes the
    chosen judge to `out` (``calibration.json``: every option tried; ``metrics.json``: the run's
    held-out real videos judged by it) and returns the metrics.

    Raises:
        ValueError: `run` is not a per-frame judge, `data` lacks successes or failures, or `out`
            holds something other than an earlier calibration (the run itself, say).
        FileNotFoundError: an asked-for checkpoint is not in `run`.
    """
    started = time.perf_counter()
    run, out = Path(run), Path(out)
    if out.resolve() == run.resolve() or (out.exists() and not (out / "calibration.json").exists()):
        raise ValueError(f"{out} exists and is not a calibrated judge (it would be replaced); give another --out")
    newest = _step(resolve_checkpoint(run))
    steps = [*config.checkpoints, newest]
    judges = {step: frame_judge(checkpoint_at(run, step)) for step in steps}  # a missing step is named here
    holds = config.hold_steps or (judges[newest].config.hold_steps,)
    cases, truth = calibration_cases(run, data, progress)
    options = []
    for step, judge in tqdm(sorted(judges.items()), desc="calibrating checkpoints", disable=not progress):
        frames = case_frame_probabilities(judge, cases)
        for hold in holds:
            scores = torch.stack([held_probability(p[None], hold)[0] for p in frames]).double()
            options.append({"checkpoint": step, "hold_steps": hold, **threshold_at_fpr(scores, truth, config.max_fpr),
                            "auc": roc_readout(scores, truth)["auc"]})
    # The most successes passed at the allowed rate; then the fewest failures, the later checkpoint.
    chosen = max(options, key=lambda option: (option["tpr"], -option["fpr"], option["checkpoint"]))
    judge = judges[chosen["checkpoint"]]
    judge.config = dataclasses.replace(judge.config, threshold=chosen["threshold"], hold_steps=chosen["hold_steps"])
    report = evaluate_judge(judge, run_scene_videos(run, 2))
    report |= {"kind": "frames", "calibrated_from": str(run), "calibration_data": [str(path) for path in data],
               "calibration_max_fpr": config.max_fpr, "calibration_cases": len(truth),
               "calibration_positives": int(truth.sum()),
               **{f"calibration_{key}": value for key, value in chosen.items()},
               "seconds": round(time.perf_counter() - started, 1)}
    settings = read_json(run / "config.json") | {"model": judge.spec(), "calibration": {
        "from": str(run), "data": [str(path) for path in data], **dataclasses.asdict(config)}}
    with atomic_directory(out, replace=True) as staging:
        save_checkpoint(staging, chosen["checkpoint"], judge, settings)
        write_run_config(staging, settings)
        write_json(staging / "calibration.json", {"chosen": chosen, "options": options})
        write_json(staging / "metrics.json", report)
    return report


def _step(checkpoint: Path) -> int:
    return int(read_json(resolve_checkpoint(checkpoint) / "trainer.json")["step"])


def frame_judge(path: Path) -> FrameJudge:
    """The per-frame judge of the run or checkpoint at `path`; any other judge is refused."""
    judge = load_judge(path)
    if not isinstance(judge, FrameJudge):
        raise ValueError(f"{path}: a {judge.backend}, not a per-frame judge; only those are calibrated "
                         "(a threshold and a hold rule over frames)")
    return judge


def calibration_cases(run: Path, data: Sequence[Path], progress: bool) -> tuple[list[tuple[Video, int]], torch.Tensor]:
    """Every case of the real episodes of `data`, read with the judge run's cameras and size: (the
    video, how many of its frames the case shows), and (N,) bool labels."""
    if not data:
        raise ValueError("calibration needs at least one dataset of labelled real episodes")
    settings = dataclasses.replace(saved_judge_config(run), extra_data=tuple(Path(path) for path in data[1:]))
    datasets, _ = judge_datasets(Path(data[0]), settings)
    cases, labels = [], []
    for dataset in datasets:
        for video in load_videos(dataset, list(range(len(dataset))), None, progress):
            for frames, _, label, _, _ in judge_cases([video]):
                cases.append((video, len(frames)))
                labels.append(label)
    truth = torch.tensor(labels, dtype=torch.bool)
    if not truth.any() or truth.all():
        raise ValueError(f"{', '.join(map(str, data))}: calibration needs both successes and failures; "
                         f"found {int(truth.sum())} successes in {len(truth)} cases")
    return cases, truth


def case_frame_probabilities(judge: FrameJudge, cases: list[tuple[Video, int]]) -> list[torch.Tensor]:
    """(T,) per-frame probabilities of each case: a video's frames are judged once, and a case cut
    from it reads its first ones (each frame is judged beside the video's first frame alone)."""
    whole: dict[int, torch.Tensor] = {}
    for video, _ in cases:
        if id(video) not in whole:
            whole[id(video)] = judge.frame_probabilities(video.frames[None], [video.instruction])[0]
    return [whole[id(video)][:length] for video, length in cases]
