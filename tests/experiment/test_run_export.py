"""`gymnast export`: a run copied without its datasets, older checkpoints and optimizer states."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch

from gymnast.cli import main
from gymnast.experiment.export import export_run
from gymnast.policy.load import load_policy
from gymnast.policy.sft import SFT_PRESETS
from gymnast.utils.checkpoint import load_checkpoint, resolve_checkpoint


@pytest.fixture(scope="module")
def run_with_bulk(tiny_dataset: Path, tmp_path_factory) -> Path:
    """A real SFT run (checkpoints at steps 3 and 6, each with its optimizer state), the dataset it
    learnt from recorded inside it, as an experiment keeps its rollouts, and a results file."""
    run = tmp_path_factory.mktemp("export") / "run"
    main(["sft", "--data", str(tiny_dataset), "--out", str(run / "sft"), "--preset", "debug"])
    shutil.copytree(tiny_dataset, run / "rollouts")
    (run / "new_scenes" / "reach").mkdir(parents=True)
    (run / "new_scenes" / "reach" / "weights.bin").write_bytes(b"\0" * 1000)
    return run


def test_the_copy_keeps_every_result_and_the_newest_model_and_leaves_out_the_bulk(run_with_bulk: Path, tmp_path: Path):
    export = export_run(run_with_bulk, tmp_path / "copy", exclude=("new_scenes/*",))
    copy = tmp_path / "copy"
    checkpoints = run_with_bulk / "sft" / "checkpoints"
    steps = SFT_PRESETS["debug"].steps
    assert sorted(path.name for path in checkpoints.iterdir()) == ["000003", f"{steps:06d}", "last"]
    assert sorted(path.name for path in (copy / "sft" / "checkpoints").iterdir()) == [f"{steps:06d}", "last"]
    assert not (copy / "rollouts").exists() and not (copy / "new_scenes" / "reach").exists()
    assert not list(copy.rglob("optimizer.pt")) and list(run_with_bulk.rglob("optimizer.pt"))
    kept = [path.relative_to(copy) for path in copy.rglob("*") if path.is_file()]
    assert kept and all((run_with_bulk / path).read_bytes() == (copy / path).read_bytes() for path in kept)
    assert export.files == len(kept)
    assert export.left_out["datasets"].files == sum(1 for path in (run_with_bulk / "rollouts").rglob("*") if path.is_file())
    assert export.left_out["checkpoints"].files == sum(1 for path in (checkpoints / "000003").iterdir())
    assert export.left_out["optimizer"].files == 1 and export.left_out["excluded"].bytes == 1000
    assert "left out datasets" in export.summary() and "left out optimizer states" in export.summary()


def test_the_copied_policy_loads_but_cannot_resume_its_training(run_with_bulk: Path, tmp_path: Path, capsys):
    export_run(run_with_bulk, tmp_path / "copy")
    original, copied = load_policy(run_with_bulk / "sft"), load_policy(tmp_path / "copy" / "sft")
    for name, tensor in original.state_dict().items():
        assert torch.equal(tensor, copied.state_dict()[name]), name
    optimizer = torch.optim.AdamW(copied.parameters())
    with pytest.raises(FileNotFoundError, match="exported without its optimizer state"):
        load_checkpoint(resolve_checkpoint(tmp_path / "copy" / "sft"), copied, optimizer)
    with pytest.raises(SystemExit):  # the command says so too, naming the checkpoint, without a traceback
        main(["sft", "--out", str(tmp_path / "copy" / "sft"), "--resume"])
    assert "exported without its optimizer state" in capsys.readouterr().err


def test_an_existing_destination_is_refused_and_left_as_it_was(run_with_bulk: Path, tmp_path: Path, capsys):
    (tmp_path / "copy").mkdir()
    (tmp_path / "copy" / "mine.txt").write_text("keep me")
    with pytest.raises(SystemExit):
        main(["export", "--run", str(run_with_bulk), "--out", str(tmp_path / "copy")])
    assert "copy exists already" in capsys.readouterr().err
    assert [path.name for path in (tmp_path / "copy").iterdir()] == ["mine.txt"]
    with pytest.raises(SystemExit):
        main(["export", "--run", str(tmp_path / "nothing"), "--out", str(tmp_path / "other")])
    assert "no such run directory" in capsys.readouterr().err and not (tmp_path / "other").exists()


def test_a_copy_that_fails_half_way_leaves_nothing_behind(run_with_bulk: Path, tmp_path: Path, monkeypatch):
    copied = []

    def copy_then_fail(source, target, follow_symlinks=True):
        if len(copied) == 3:
            raise OSError("disk full")
        copied.append(source)
        return shutil.copyfile(source, target, follow_symlinks=follow_symlinks)

    monkeypatch.setattr("gymnast.experiment.export.shutil.copy2", copy_then_fail)
    with pytest.raises(OSError, match="disk full"):
        export_run(run_with_bulk, tmp_path / "copy")
    assert list(tmp_path.iterdir()) == []


def test_the_command_prints_what_it_copied_and_left_out(run_with_bulk: Path, tmp_path: Path, capsys):
    main(["export", "--run", str(run_with_bulk), "--out", str(tmp_path / "copy"), "--datasets", "--optimizer"])
    printed = capsys.readouterr().out
    assert f"{tmp_path / 'copy'}:" in printed and "left out datasets" not in printed
    assert (tmp_path / "copy" / "rollouts" / "meta" / "info.json").is_file()
    assert list((tmp_path / "copy").rglob("optimizer.pt"))
