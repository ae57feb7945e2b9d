"""The learned judge: its metrics on known labels, training end to end, and serving it over HTTP."""

import dataclasses
import json

import pytest
import torch
from robot_datasets import write_robot_dataset

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.video import LearnedJudge, judged_frame_indices
from gymnast.reward.chat.serve import judge_server
from gymnast.reward.judges.measure import evaluate_judge
from gymnast.reward.judges.train import JUDGE_PRESETS, load_judge, train_judge
from gymnast.reward.judges.videos import load_videos
from gymnast.reward.chat.vlm import VLMJudge, VLMJudgeConfig
from gymnast.world_model.train import WM_PRESETS, train_world_model

# The tiny dataset's scene drawer-close/0 is held out at 0.25 (see tests/world_model/test_train.py).
DEBUG = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25)


def always(answer: bool) -> LearnedJudge:
    """A real judge whose head ignores its input and says `answer` with certainty."""
    judge = LearnedJudge(JudgeConfig(width=32, image_size=32))
    last = judge.head[-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.constant_(last.bias, 20.0 if answer else -20.0)
    return judge.eval()


@pytest.fixture(scope="module")
def videos(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    return load_videos(dataset, list(range(len(dataset.lengths))), wm=None, progress=False)


def test_the_judge_looks_at_the_first_middle_and_last_two_frames():
    assert judged_frame_indices(11) == [0, 5, 9, 10]
    assert judged_frame_indices(2) == [0, 0, 0, 1]


def test_metrics_on_known_labels(videos):
    positives = sum(bool(v.success[-1]) for v in videos)
    yes, no = evaluate_judge(always(True), videos), evaluate_judge(always(False), videos)
    assert yes["real_tpr"] == 1.0 and yes["real_fpr"] == 1.0
    assert no["real_tpr"] == 0.0 and no["real_fpr"] == 0.0
    assert yes["real_positives"] == positives > 0 and yes["real_negatives"] > yes["real_whole_failures"]
    assert yes["real_accuracy"] == pytest.approx(positives / (positives + yes["real_negatives"]), abs=1e-4)
    assert "imagined_tpr" not in yes  # no world model, no imagined videos
    assert yes["real_roc"] == {"auc": 0.5, "at_tpr": 0.95, "lowest_fpr": 1.0}  # one score for all: no ranking


def test_training_with_a_world_model_reports_real_and_imagined_figures(tiny_dataset, tmp_path):
    train_world_model(tiny_dataset, tmp_path / "wm", dataclasses.replace(WM_PRESETS["debug"], heldout_fraction=0.25), progress=False)
    report = train_judge(tiny_dataset, tmp_path / "judge", DEBUG, wm=tmp_path / "wm", progress=False)
    for key in ("real_tpr", "real_fpr", "imagined_tpr", "imagined_fpr"):
        assert 0.0 <= report[key] <= 1.0
    assert (tmp_path / "judge" / "metrics.json").exists()
    assert load_judge(tmp_path / "judge").config.image_size == 32


def test_the_vlm_client_scores_videos_through_serve_judge(tiny_dataset, tmp_path, videos):
    train_judge(tiny_dataset, tmp_path / "judge", DEBUG, progress=False)
    judge = load_judge(tmp_path / "judge")
    video = torch.stack([videos[0].frames[:10], videos[1].frames[:10]])  # (2, 10, 32, 32, 3)
    instructions = [videos[0].instruction, videos[1].instruction]
    with judge_server(tmp_path / "judge") as server:
        client = VLMJudge(VLMJudgeConfig(model="gymnast-judge", base_url=server.url, samples=1, frame_every=3))
        scores = client.score(video, instructions)
        assert server.requests_served == 2
    # The server judged the JPEG-decoded frames 0, 3, 6, 9: the judge's own answer on those frames.
    direct = judge.score(video[:, [0, 3, 6, 9]], instructions)
    assert set(scores.tolist()) <= {0.0, 1.0} and client.stats["malformed"] == 0
    assert (scores == direct).float().mean() >= 0.5  # JPEG may flip a borderline call, not both


def test_cli_train_judge_runs(tiny_dataset, tmp_path, capsys):
    main(["train-judge", "--data", str(tiny_dataset), "--out", str(tmp_path / "j"), "--preset", "debug"])
    assert "judge:" in capsys.readouterr().out
    main(["train-judge", "--out", str(tmp_path / "j"), "--resume"])  # the data comes from the run
    assert "judge:" in capsys.readouterr().out


def test_cli_eval_judge_measures_a_judge_through_its_name(tiny_dataset, tmp_path, capsys):
    train_judge(tiny_dataset, tmp_path / "judge", DEBUG, progress=False)
    out = tmp_path / "eval.json"
    main(["eval-judge", "--reward", f"judge:{tmp_path / 'judge'}", "--data", str(tiny_dataset), "--out", str(out),
          "--heldout-fraction", "0.25"])
    report = json.loads(out.read_text())
    assert report["real_positives"] + report["real_negatives"] > 0 and report["real_unscored"] == 0
    assert report["camera"] == "front"
    # Another robot's dataset with two cameras: the one named is judged, its actions read by their key.
    robot = write_robot_dataset(tmp_path / "robot", episodes=6, steps=10, height=96, width=96, cameras=("front", "wrist"))
    main(["eval-judge", "--reward", f"judge:{tmp_path / 'judge'}", "--data", str(robot), "--out", str(out),
          "--heldout-fraction", "0.5", "--camera", "wrist", "--action-key", "action"])
    report = json.loads(out.read_text())
    assert report["camera"] == "wrist" and report["real_positives"] + report["real_negatives"] > 0
    with pytest.raises(SystemExit):
        main(["eval-judge", "--reward", "sim", "--data", str(tiny_dataset), "--out", str(out)])
    assert "measures judges" in capsys.readouterr().err


def test_serve_judge_survives_faults_and_the_client_recovers_or_says_nan(tiny_dataset, tmp_path, videos):
    train_judge(tiny_dataset, tmp_path / "judge", DEBUG, progress=False)
    video, instruction = videos[0].frames[None, :10], [videos[0].instruction]
    config = VLMJudgeConfig(model="gymnast-judge", base_url="", samples=1, frame_every=3, max_retries=2, backoff_s=0.01, timeout_s=0.5)
    with judge_server(tmp_path / "judge", faults=["429", "500"]) as server:
        client = VLMJudge(dataclasses.replace(config, base_url=server.url))
        assert client.score(video, instruction).item() in (0.0, 1.0) and client.stats["retries"] == 2
    with judge_server(tmp_path / "judge", faults=["slow:2", "500", "garbage"]) as server:
        client = VLMJudge(dataclasses.replace(config, base_url=server.url))
        assert torch.isnan(client.score(video, instruction)).all()  # timeout, 500, then no ANSWER line
        assert client.stats["malformed"] == 1
