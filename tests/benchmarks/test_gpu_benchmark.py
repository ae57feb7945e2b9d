"""benchmarks/gpu.py and benchmarks/lerobot_gpu.py keep working where no GPU is: every measurement runs at
toy sizes on the CPU."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "gpu.py"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def starts(tmp_path_factory) -> Path:
    """Start states at the committed models' 96 px."""
    data = tmp_path_factory.mktemp("starts")
    collect(CollectConfig(tasks="reach-v3", episodes_per_task=2, noise=(0.0,), workers=1,
                          env=EnvConfig(image_size=96, horizon=100)), data, progress=False)
    return data


@pytest.mark.slow
@pytest.mark.skipif(not (ROOT / "results/world_model/wm").exists(), reason="needs the committed world model and judge")
def test_every_measurement_runs_at_toy_sizes_on_the_cpu(tmp_path, starts):
    data = starts
    out = tmp_path / "gpu.json"
    done = _run("--device", "cpu", "--small", "--data", str(data), "--tasks", "reach-v3", "--out", str(out), "--profile")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "self_cpu_time_total" in out.with_suffix(".profile.txt").read_text()
    result = json.loads(out.read_text())
    assert result["device"] == "cpu" and result["sizes"]["policy_batch"] == 4
    assert result["imagined_fps_b4"] > 0 and result["imagined_fps_b8"] > 0
    assert result["imagined_obs_per_s_two_cameras_b4"] > 0 and result["model_fps_b4"] > 0
    assert result["imagined_obs_per_s_three_cameras_b4"] > 0 and result["wm_train_step_s"]["default"] > 0
    setups = {"front", "front+gripper", "front+gripper+hand", "front+gripper+state"}
    for speeds in (result["policy_train_obs_per_s"], result["policy_sample_obs_per_s"]):
        assert set(speeds) == setups and min(speeds.values()) > 0
    assert result["rl_step"]["rollouts_per_step"] == 4 and result["rl_step_s"] > 0
    assert result["rl_segment_step"]["horizon"] == 5 and result["rl_segment_step"]["step_s"] > 0
    chunk = result["chunk_model"]  # the frame-per-chunk model, beside the committed one
    assert chunk["actions_per_frame"] == 5 and chunk["imagined_actions_per_s_b4"] > 0 and chunk["model_actions_per_s_b8"] > 0
    assert chunk["wm_train_step_s"] > 0 and chunk["rl_step"]["rollouts_per_step"] == 4


def test_without_a_gpu_it_measures_nothing_and_says_why(tmp_path):
    done = _run("--device", "cpu", "--out", str(tmp_path / "gpu.json"))
    assert done.returncode != 0 and "measures a GPU" in done.stderr
    assert not (tmp_path / "gpu.json").exists()


def test_an_unknown_measurement_to_skip_is_named(tmp_path):
    done = _run("--device", "cpu", "--small", "--skip", "policy,judge", "--out", str(tmp_path / "gpu.json"))
    assert done.returncode != 0 and "unknown ['judge']" in done.stderr


@pytest.mark.slow
@pytest.mark.skipif(not (ROOT / "results/world_model/wm").exists(), reason="needs the committed world model")
def test_the_smolvla_grpo_step_runs_at_toy_sizes_on_the_cpu(tmp_path, starts):
    """benchmarks/lerobot_gpu.py: a tiny SmolVLA through `gymnast rl --policy lerobot:...` in imagination."""
    out = tmp_path / "lerobot_gpu.json"
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "lerobot_gpu.py"), "--device", "cpu", "--small",
                           "--data", str(starts), "--tasks", "reach-v3", "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(out.read_text())
    assert result["step"]["rollouts_per_step"] == 4 and result["step"]["policy_calls"] > 0
    assert result["grpo_step_s"] > 0 and 0 < result["parameters"] < 10**6
