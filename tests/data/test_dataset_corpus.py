"""Datasets as people publish them (`dataset_corpus`): each whose meaning is clear is read, says what it
assumed, and trains the world model, the policy and the judge at debug size; each other is refused
with one line naming the file, the field and the fix. No traceback either way."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from dataset_corpus import CORPUS, build

from gymnast.cli import main
from gymnast.data.check import check_dataset
from gymnast.data.lerobot import EpisodeDataset

CLEAR = [name for name, (_, _, error) in CORPUS.items() if error is None]
REFUSED = [name for name, (_, _, error) in CORPUS.items() if error is not None]
PRACTISED = ("published_bimanual", "depth_images")
"""Datasets the policy also practises on in imagination (the rest train the three models)."""


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> dict[str, Path]:
    """Every corpus dataset, written once."""
    root = tmp_path_factory.mktemp("corpus")
    return {name: build(root / name, name) for name in CORPUS}


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    """`gymnast ARGV` in this process: (exit status, stdout, stderr)."""
    try:
        main(argv)
        code = 0
    except SystemExit as exit_info:
        code = exit_info.code
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err, argv
    return code, out, err


@pytest.mark.parametrize("name", CLEAR)
def test_a_dataset_whose_meaning_is_clear_is_read_and_says_what_it_assumed(name, corpus, capsys):
    dataset = EpisodeDataset(corpus[name])
    episodes = [dataset.load(i) for i in range(len(dataset))]
    assert all(len(e.frames) == e.length + 1 and e.frames.shape[1:] == dataset.camera_shape for e in episodes)
    assert dataset.action_stats.dim == dataset.action_dim
    code, out, _ = _run(["inspect", "--data", str(corpus[name])], capsys)
    assert code == 0 and f"{len(dataset)} episodes" in out
    code, out, _ = _run(["inspect", "--check", "--data", str(corpus[name])], capsys)
    assert code == 0 and "training can proceed" in out and "refused" not in out
    # Every corpus dataset lacks the stats files; each but one departs in at least one more way, which is named
    # (images in the rows are LeRobot's own 'image' features).
    found = [d for d in check_dataset(corpus[name]) if not d.field.startswith("meta/")]
    assert found or name == "images_in_rows", out


@pytest.mark.parametrize("name", REFUSED)
def test_a_dataset_whose_meaning_is_unclear_is_refused_in_one_line_naming_the_fix(name, corpus, capsys):
    message = CORPUS[name][2]
    code, _, _ = _run(["inspect", "--data", str(corpus[name])], capsys)
    assert code in (0, 2)  # a summary (of the metadata, or the flags to pass) or the error, never a traceback
    for command in ("train-wm", "sft", "train-judge"):
        out = corpus[name].parent / f"{name}_{command}"
        code, _, err = _run([command, "--data", str(corpus[name]), "--out", str(out), "--preset", "debug"], capsys)
        errors = [line for line in err.splitlines() if line.startswith("gymnast: error:")]  # beside progress bars
        assert code == 2 and len(errors) == 1 and message in errors[0], err
    code, out, _ = _run(["inspect", "--check", "--data", str(corpus[name])], capsys)
    assert code == 1 and "training cannot proceed" in out and message in out


@pytest.mark.slow
@pytest.mark.parametrize("name", CLEAR)
def test_a_dataset_whose_meaning_is_clear_trains_every_model_at_debug_size(name, corpus, tmp_path, capsys):
    runs = {command: tmp_path / command for command in ("train-wm", "sft", "train-judge")}
    for command, out in runs.items():
        code, _, err = _run([command, "--data", str(corpus[name]), "--out", str(out), "--preset", "debug"], capsys)
        assert code == 0, err
    if name in PRACTISED:
        out = tmp_path / "rl"
        code, _, err = _run(["rl", "--policy", str(runs["sft"]), "--env", "imagined", "--wm", str(runs["train-wm"]),
                             "--reward", f"judge:{runs['train-judge']}", "--out", str(out), "--preset", "debug",
                             "--no-real-eval", "--watch-every", "0"], capsys)
        assert code == 0, err
        assert json.loads((out / "summary.json").read_text())["real_interactions"] == 0


@pytest.mark.parametrize("name", CLEAR)
def test_frames_decoded_alone_are_those_of_the_whole_episode(name, corpus):
    dataset = EpisodeDataset(corpus[name])
    for i in range(len(dataset)):
        frames = dataset.load(i).observed_frames
        np.testing.assert_array_equal(dataset.first_frame(i), frames[0])
        np.testing.assert_array_equal(dataset.frames(i, 1, 3), frames[1:3])
        np.testing.assert_array_equal(dataset.frames(i, len(frames) - 2, len(frames)), frames[-2:])
