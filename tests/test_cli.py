"""CLI smoke runs of the subcommands that are not covered elsewhere."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, plan_episodes, record_episode
from gymnast.envs.parallel import parallel_map


def test_tasks_lists_every_mt10_task_with_its_paraphrases(capsys):
    main(["tasks", "--task-set", "mt10"])
    out = capsys.readouterr().out
    assert out.count("-v3") == 10 and len(out.splitlines()) >= 50


def test_contact_sheet_writes_a_picture_and_pixel_counts(tmp_path: Path):
    out = tmp_path / "sheet.png"
    main(["contact-sheet", "--tasks", "reach-v3,drawer-open-v3", "--out", str(out), "--env.image-size", "48"])
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pixels = json.loads(out.with_suffix(".json").read_text())["pixels"]
    assert pixels["reach-v3"]["goal marker"] > 0 and pixels["drawer-open-v3"]["drawer"] > 0


def test_inspect_summarises_a_dataset_and_draws_its_episodes(tmp_path: Path, capsys):
    data = tmp_path / "data"
    main(["collect", "--tasks", "reach-v3", "--episodes-per-task", "1", "--out", str(data), "--workers", "1",
          "--env.image-size", "32", "--env.horizon", "20"])
    main(["inspect", "--data", str(data), "--sheet", str(tmp_path / "episodes.png")])
    out = capsys.readouterr().out
    assert "v3.0, 2 episodes" in out and "reach-v3" in out
    assert (tmp_path / "episodes.png").exists()


def test_bad_input_exits_with_a_message_not_a_traceback(tmp_path: Path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["collect", "--tasks", "no-such-task", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "unknown task 'no-such-task'" in capsys.readouterr().err


def test_parallel_workers_record_the_same_episodes_as_one_process():
    config = CollectConfig(tasks="reach-v3", episodes_per_task=2, failure_fraction=0.5,
                           env=EnvConfig(image_size=32, horizon=20))
    jobs = plan_episodes(config)
    parallel = {episode.info.key: episode for episode in parallel_map(record_episode, jobs, workers=2)}
    for job in jobs:
        serial = record_episode(job)
        np.testing.assert_array_equal(parallel[job.key].frames, serial.frames)
        np.testing.assert_array_equal(parallel[job.key].actions, serial.actions)


def test_gap_report_measures_each_level_and_writes_json_and_markdown(tmp_path: Path):
    out = tmp_path / "gap.json"
    main(["gap-report", "--tasks", "reach-v3", "--episodes", "1", "--levels", "strong", "--workers", "1",
          "--env.image-size", "32", "--env.horizon", "60", "--out", str(out)])
    report = json.loads(out.read_text())
    overall = report["levels"]["strong"]["overall"]
    assert overall["real_expert_success"] == 1.0  # the expert solves reach in the real world
    assert overall["hand_divergence_cm_final"] > 0.5  # the strong gap's physics move the hand elsewhere
    assert "| strong |" in out.with_suffix(".md").read_text()
