"""--tracker: settings, metrics, videos and plots reach TensorBoard and W&B (offline: the tests set
WANDB_MODE=offline in conftest.py), a resumed run continues its trackers, and saved runs from before
the setting still load."""

import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from gymnast.cli import main
from gymnast.cli.settings import resolve
from gymnast.experiment.dyna import DYNA_PRESETS, DynaConfig
from gymnast.reward.judges.train import JUDGE_PRESETS, train_judge
from gymnast.rl.config import RL_PRESETS, RLConfig, saved_rl_settings
from gymnast.utils.atomic import write_json
from gymnast.utils.metrics import MetricsLog
from gymnast.utils.settings import from_json
from gymnast.utils.trackers import gif_bytes, open_trackers, parse_trackers
from gymnast.utils.video import encode_video

VIDEO = np.random.default_rng(0).integers(0, 256, (12, 16, 32, 3), dtype=np.uint8)


def board(run: Path) -> EventAccumulator:
    events = EventAccumulator(str(run / "tensorboard"), size_guidance={"images": 0, "scalars": 0, "tensors": 0})
    events.Reload()
    return events


def wandb_run(run: Path) -> Path:
    """The newest offline W&B run folder of a run."""
    (folder,) = [path for path in (run / "wandb").glob("offline-run-*") if path.is_dir()][-1:]
    return folder


def test_tracker_names_parse_and_an_unknown_one_is_refused():
    assert parse_trackers("none") == () and parse_trackers("") == ()
    assert parse_trackers("tensorboard,wandb") == ("tensorboard", "wandb")
    with pytest.raises(ValueError, match="none or any of tensorboard, wandb"):
        parse_trackers("mlflow")
    with pytest.raises(SystemExit):
        main(["train-judge", "--out", "nowhere", "--tracker", "tensorboard,tensorboard"])


def test_wandb_asked_for_without_its_package_names_the_extra(tmp_path, monkeypatch):
    found = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "wandb" else found(name, *a))
    with pytest.raises(ImportError, match=r"pip install 'world-gymnast\[wandb\]'"):
        open_trackers(["wandb"], tmp_path)
    assert not (tmp_path / "wandb").exists()


def test_settings_metrics_videos_and_plots_reach_tensorboard_and_wandb(tmp_path):
    run = tmp_path / "run"
    encode_video(tmp_path / "clip.mp4", VIDEO, fps=10)
    Image.fromarray(VIDEO[0]).save(tmp_path / "plot.png")
    log = MetricsLog(run, tracker=open_trackers(["tensorboard", "wandb"], run, kind="sft", config={"lr": 0.1, "data": Path("d")}))
    for step in (1, 2, 3):
        log.log(step, {"train/loss": 1.0 / step})
    log.video("rollout/video", 3, VIDEO)
    log.video("wm/video", 3, tmp_path / "clip.mp4")
    log.image("plots/curve", 3, tmp_path / "plot.png")
    log.log(4, {"train/loss": 0.25})  # after the videos encoded in the background: none of them is out of order
    log.close()
    assert [json.loads(line)["step"] for line in (run / "metrics.jsonl").read_text().splitlines()] == [1, 2, 3, 4]
    events = board(run)
    assert [event.value for event in events.Scalars("train/loss")] == pytest.approx([1.0, 0.5, 1 / 3, 0.25])
    assert set(events.Tags()["images"]) == {"rollout/video", "wm/video", "plots/curve"}
    gif = events.Images("rollout/video")[0].encoded_image_string
    assert gif.startswith(b"GIF89a") and Image.open(__import__("io").BytesIO(gif)).n_frames == len(VIDEO)
    assert '"lr": 0.1' in events.Tensors("config/text_summary")[0].tensor_proto.string_val[0].decode()
    media = wandb_run(run) / "files" / "media"
    assert {path.suffix for path in media.rglob("*.*")} == {".gif", ".mp4", ".png"}
    assert (wandb_run(run) / f"run-{(run / 'wandb' / 'run_id').read_text()}.wandb").is_file()


def test_a_resumed_run_continues_its_wandb_run_and_drops_tensorboard_events_past_the_checkpoint(tmp_path):
    first = open_trackers(["tensorboard", "wandb"], tmp_path)
    for step in (1, 2, 3, 4):
        first.log_metrics(step, {"train/loss": float(step)})
    first.close()
    run_id = (tmp_path / "wandb" / "run_id").read_text()
    again = open_trackers(["tensorboard", "wandb"], tmp_path, resume_step=2)
    again.log_metrics(3, {"train/loss": 30.0})
    again.close()
    assert (tmp_path / "wandb" / "run_id").read_text() == run_id
    assert [(e.step, e.value) for e in board(tmp_path).Scalars("train/loss")] == [(1, 1.0), (2, 2.0), (3, 30.0)]
    open_trackers(["wandb"], tmp_path).close()  # a new run in the same folder: a new W&B run
    assert (tmp_path / "wandb" / "run_id").read_text() != run_id


def test_a_gif_preview_keeps_every_frame_of_a_short_video():
    assert Image.open(__import__("io").BytesIO(gif_bytes(VIDEO))).n_frames == len(VIDEO)


def test_an_rl_run_saved_with_the_tensorboard_switch_still_loads(tmp_path):
    for switch, trackers in ((True, ("tensorboard",)), (False, ())):
        saved = {k: v for k, v in dataclasses.asdict(RL_PRESETS["debug"]).items() if k != "tracker"} | {"tensorboard": switch}
        write_json(tmp_path / "config.json", {"run": {"policy": "p", "env": "sim", "reward": "sim"}, "rl": saved})
        assert saved_rl_settings(tmp_path)[1].tracker == trackers
        dyna = json.loads(json.dumps(dataclasses.asdict(DYNA_PRESETS["debug"]), default=str))
        dyna["rl"] = saved
        assert from_json(DynaConfig, dyna).rl.tracker == trackers
    assert RLConfig().tracker == ("tensorboard",)


def test_a_trainer_logs_its_settings_metrics_and_held_out_figures_to_its_trackers(tiny_dataset, tmp_path):
    config = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25, tracker=("tensorboard", "wandb"))
    train_judge(tiny_dataset, tmp_path / "judge", config, progress=False)
    events = board(tmp_path / "judge")
    assert {"train/loss", "eval/real_tpr"} <= set(events.Tags()["scalars"])
    assert "config/text_summary" in events.Tags()["tensors"]
    assert (wandb_run(tmp_path / "judge") / f"run-{(tmp_path / 'judge' / 'wandb' / 'run_id').read_text()}.wandb").is_file()


def test_resume_may_log_elsewhere_in_a_nested_setting_too(tmp_path):
    saved = DYNA_PRESETS["debug"]
    config, _ = resolve("dyna", tmp_path, True, saved, overrides={"rl.tracker": ("wandb",), "rounds": saved.rounds},
                        inputs={}, saved=lambda: (saved, {}))
    assert config.rl.tracker == ("wandb",) and config.rounds == saved.rounds
    with pytest.raises(ValueError, match="--rounds 1 disagrees"):
        resolve("dyna", tmp_path, True, saved, overrides={"rounds": 1}, inputs={}, saved=lambda: (saved, {}))
