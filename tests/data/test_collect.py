"""`gymnast collect`: the plan, the dataset it writes, resuming, and bad input."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect, plan_episodes, record_episode
from gymnast.data.lerobot import EpisodeDataset
from gymnast.utils.video import psnr

TINY = EnvConfig(image_size=32, horizon=30)


def test_plan_cycles_noise_levels_and_adds_failures():
    config = CollectConfig(tasks="reach-v3,push-v3", episodes_per_task=4, noise=(0.0, 0.3), failure_fraction=0.5)
    jobs = plan_episodes(config)
    reach = [job for job in jobs if job.task == "reach-v3"]
    assert [(j.behaviour, j.noise) for j in reach] == [
        ("expert", 0.0), ("noisy_expert", 0.3), ("expert", 0.0), ("noisy_expert", 0.3),
        ("random", 0.0), ("wrong_task_expert", 0.0),
    ]
    assert len({job.key for job in jobs}) == len(jobs) == 12


def test_evaluation_seeds_are_never_collected():
    with pytest.raises(ValueError, match="evaluation seeds"):
        CollectConfig(first_seed=1_000_000)


def test_cli_collect_writes_a_v3_dataset_that_reads_back_within_the_codec_error(tmp_path: Path, capsys):
    out = tmp_path / "data"
    main(["collect", "--tasks", "drawer-open-v3", "--episodes-per-task", "2", "--out", str(out),
          "--workers", "1", "--env.image-size", "32", "--env.horizon", "30"])
    assert "drawer-open-v3" in capsys.readouterr().out
    assert (out / "meta" / "info.json").exists() and (out / "meta" / "tasks.parquet").exists()
    dataset = EpisodeDataset(out)
    assert dataset.info["codebase_version"] == "v3.0"
    config = CollectConfig(tasks="drawer-open-v3", episodes_per_task=2, env=TINY)
    jobs = plan_episodes(config)
    assert sorted(info.key for info in dataset.episodes) == sorted(job.key for job in jobs)
    codec_floor = dataset.info["gymnast"]["video_psnr_db"]["min"]
    assert codec_floor >= 40.0
    for i, info in enumerate(dataset.episodes):
        recorded = dataset.load(i)
        fresh = record_episode(next(job for job in jobs if job.key == info.key))  # deterministic
        np.testing.assert_array_equal(recorded.actions, fresh.actions)
        np.testing.assert_array_equal(recorded.states, fresh.states)
        assert recorded.info == fresh.info
        assert psnr(recorded.frames, fresh.frames).per_frame.min() >= codec_floor - 1e-6


def test_rerun_skips_finished_episodes_and_extends_with_new_ones(tmp_path: Path):
    config = CollectConfig(tasks="reach-v3", episodes_per_task=2, failure_fraction=0, workers=1, env=TINY)
    collect(config, tmp_path, progress=False)
    first = EpisodeDataset(tmp_path).info["total_frames"]
    collect(config, tmp_path, progress=False)
    assert EpisodeDataset(tmp_path).info["total_frames"] == first
    bigger = CollectConfig(tasks="reach-v3", episodes_per_task=3, failure_fraction=0, workers=1, env=TINY)
    table = collect(bigger, tmp_path, progress=False)
    assert len(EpisodeDataset(tmp_path)) == 3
    assert sum(cell[1] for cell in table["reach-v3"].values()) == 3


def test_rerun_with_other_env_settings_is_refused_and_names_the_field(tmp_path: Path):
    collect(CollectConfig(tasks="reach-v3", episodes_per_task=1, failure_fraction=0, workers=1, env=TINY), tmp_path,
            progress=False)
    other = EnvConfig(image_size=40, horizon=30)
    with pytest.raises(ValueError, match="'env'"):
        collect(CollectConfig(tasks="reach-v3", episodes_per_task=1, workers=1, env=other), tmp_path, progress=False)


@pytest.mark.slow
def test_collection_killed_mid_run_resumes_without_loss_or_duplicates(tmp_path: Path):
    out = tmp_path / "data"
    args = ["collect", "--tasks", "reach-v3", "--episodes-per-task", "6", "--failure-fraction", "0",
            "--workers", "1", "--flush-every", "2", "--out", str(out), "--env.image-size", "32",
            "--env.horizon", "40"]
    process = subprocess.Popen([sys.executable, "-m", "gymnast.cli", *args], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, env=dict(os.environ))
    deadline = time.time() + 120
    # Kill it once something is committed and more is staged, i.e. in the middle of the work.
    while time.time() < deadline and process.poll() is None:
        committed = (out / "meta" / "info.json").exists()
        staged = list((out / ".staging").glob("*.npz")) if (out / ".staging").exists() else []
        if committed and staged:
            break
        time.sleep(0.05)
    assert process.poll() is None, "collection finished before it could be interrupted"
    process.send_signal(signal.SIGKILL)
    process.wait()
    interrupted = EpisodeDataset(out)  # the last committed state is a readable dataset
    assert 0 < len(interrupted) < 6
    main(args)
    dataset = EpisodeDataset(out)
    keys = [info.key for info in dataset.episodes]
    assert len(keys) == len(set(keys)) == 6
    assert sorted(info.seed for info in dataset.episodes) == list(range(6))
