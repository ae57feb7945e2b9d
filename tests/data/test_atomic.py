"""gymnast.utils.atomic: a file is either the old one or the new one, and no temp file is left."""

from __future__ import annotations

import json
import os

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from gymnast.utils.atomic import atomic_path, is_temporary, write_bytes, write_json, write_parquet


def test_writes_replace_the_file_and_leave_no_temporary(tmp_path):
    path = tmp_path / "sub" / "info.json"
    write_json(path, {"a": 1})
    write_json(path, {"a": 2})
    write_parquet(tmp_path / "t.parquet", pa.table({"x": [1, 2]}))
    assert json.loads(path.read_text()) == {"a": 2}
    assert pq.read_table(tmp_path / "t.parquet").column("x").to_pylist() == [1, 2]
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["info.json", "t.parquet"]


def test_a_failed_write_keeps_the_old_file(tmp_path):
    path = tmp_path / "info.json"
    write_json(path, {"a": 1})
    with pytest.raises(RuntimeError), atomic_path(path) as tmp:
        tmp.write_text("half")
        assert is_temporary(tmp)
        raise RuntimeError("crash")
    assert json.loads(path.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["info.json"]


def test_json_refuses_infinity(tmp_path):
    with pytest.raises(ValueError):
        write_json(tmp_path / "x.json", {"psnr": float("inf")})
    assert not any(tmp_path.iterdir())


def test_written_files_get_ordinary_permissions_not_private_ones(tmp_path):
    target = tmp_path / "shared.bin"
    write_bytes(target, b"x")
    mask = os.umask(0)
    os.umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask


def test_a_directory_appears_whole_or_not_at_all(tmp_path):
    from gymnast.utils.atomic import atomic_directory

    target = tmp_path / "run" / "copy"
    with pytest.raises(RuntimeError), atomic_directory(target) as staging:
        (staging / "half.txt").write_text("written before the failure")
        raise RuntimeError("the copy failed half-way")
    assert not target.exists() and list((tmp_path / "run").iterdir()) == []

    with atomic_directory(target) as staging:
        (staging / "whole.txt").write_text("first")
    assert (target / "whole.txt").read_text() == "first"

    with pytest.raises(OSError), atomic_directory(target) as staging:  # no replace: an existing one stays
        (staging / "whole.txt").write_text("second")
    assert (target / "whole.txt").read_text() == "first"
    with atomic_directory(target, replace=True) as staging:
        (staging / "other.txt").write_text("second")
    assert [p.name for p in target.iterdir()] == ["other.txt"]
    assert sorted(p.name for p in target.parent.iterdir()) == ["copy"]
