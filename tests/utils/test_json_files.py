"""The JSON files gymnast writes, read back: a file cut short or edited is named with the place."""

from __future__ import annotations

from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.utils.atomic import read_json, write_json


def test_what_write_json_wrote_reads_back(tmp_path: Path):
    write_json(tmp_path / "record.json", {"stage": "sft", "wall_s": 12.5, "path": None})
    assert read_json(tmp_path / "record.json") == {"stage": "sft", "wall_s": 12.5, "path": None}


def test_a_file_cut_short_is_named_with_the_line_and_column(tmp_path: Path):
    path = tmp_path / "record.json"
    path.write_text('{\n    "stage": "sft",\n    "wall_')
    with pytest.raises(ValueError, match=rf"{path}: not valid JSON \(.* at line 3, column 5\); it was cut short"):
        read_json(path)
    path.write_bytes(b"\xff\xfe{}")
    with pytest.raises(ValueError, match=rf"{path}: not a JSON text file"):
        read_json(path)
    with pytest.raises(FileNotFoundError):
        read_json(tmp_path / "missing.json")


def test_resuming_a_run_whose_settings_were_cut_short_names_the_file(tmp_path: Path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text('{"rl": {"steps": 4')
    with pytest.raises(SystemExit):
        main(["rl", "--out", str(run), "--resume"])
    assert f"gymnast: error: {run / 'config.json'}: not valid JSON" in capsys.readouterr().err
