"""Practice in short segments from real keyframes, rewarded by a grounded world model's reward
head: GRPO runs on it, the keyframes are restored exactly in the real world for the watch and the
signal, and the evaluation still runs whole episodes from first frames."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.rl.config import RLConfig
from gymnast.world_model.train_state import StateTrainConfig, train_state_model

RESULTS = Path(__file__).resolve().parents[2] / "results"
POLICY, WORLD_MODEL = RESULTS / "sft" / "policy", RESULTS / "world_model" / "wm"


@pytest.fixture(scope="module")
def state_run(rl_dataset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("state")
    train_state_model(rl_dataset, out, StateTrainConfig(steps=40, batch_size=16, unroll=4, heldout_fraction=0.0),
                      progress=False)
    return out


@pytest.mark.slow
def test_grpo_practises_segments_from_keyframes_on_the_state_models_reward(rl_dataset, state_run, tmp_path):
    out = tmp_path / "rl"
    main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", f"state:{state_run}",
          "--data", str(rl_dataset), "--out", str(out), "--preset", "debug", "--keyframes", "uniform",
          "--horizon", "10", "--eval-horizon", "15", "--watch-every", "1"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 2 and summary["real_interactions"] == 0
    assert summary["watch_real_interactions"] > 0  # keyframes replayed for real: prefixes plus segments
    metrics = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert any("reward/mean" in m for m in metrics)
    saved = json.loads((out / "config.json").read_text())["rl"]
    assert saved["keyframes"] == "uniform" and saved["horizon"] == 10 and saved["eval_horizon"] == 15


@pytest.mark.slow
def test_practice_in_the_real_world_from_keyframes_counts_the_replays_that_restore_them(rl_dataset, tmp_path):
    out = tmp_path / "real"
    main(["rl", "--policy", str(POLICY), "--env", "real", "--reward", "sim-dense", "--data", str(rl_dataset),
          "--out", str(out), "--preset", "debug", "--keyframes", "uniform", "--horizon", "5", "--eval-horizon", "5",
          "--eval-episodes", "1", "--workers", "1"])
    summary = json.loads((out / "summary.json").read_text())
    metrics = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    rollouts = 2 * 2  # the debug preset's starts x group, one round a step (every group kept)
    segments = sum(round(m["rollout/length"] * rollouts) for m in metrics if "rollout/length" in m)
    assert all(m["rollout/rounds"] == 1 for m in metrics if "rollout/rounds" in m)
    assert summary["real_interactions"] > segments  # the keyframes' prefixes were replayed for real


@pytest.mark.slow
def test_the_signal_of_segments_from_keyframes_is_held_against_their_real_replays(rl_dataset, state_run, tmp_path):
    out = tmp_path / "signal"
    main(["rl-signal", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--reward", f"state:{state_run}",
          "--out", str(out), "--tasks", "reach-v3", "--starts-per-task", "2", "--group-size", "4", "--horizons", "5",
          "10", "--batch", "8", "--workers", "1", "--data", str(rl_dataset), "--keyframes", "uniform",
          "--heldout-fraction", "0"])
    report = json.loads((out / "signal.json").read_text())
    prefixes = sum(record["keyframe"] for record in report["rollouts"])
    assert report["interactions"] == 8 * 10 + prefixes  # the restores are real interactions too
    assert any(record["keyframe"] > 0 for record in report["rollouts"])
    for record in report["rollouts"]:
        assert set(record["readouts"]) == {"score", "verdict", "real dense reward (reference)"}
        assert set(record["real_return"]) == {"5", "10"}
    dense = next(r for r in report["readouts"] if r["readout"] == "real dense reward (reference)" and r["horizon"] == 10)
    assert dense["return_correlation"] is None or dense["return_correlation"] == pytest.approx(1.0)
    assert "keyframes (uniform)" in (out / "signal.md").read_text()


def test_keyframes_are_refused_with_starts_that_are_first_frames():
    with pytest.raises(ValueError, match="--keyframes uniform"):
        RLConfig(keyframes="uniform", fresh_scenes=True)
    with pytest.raises(ValueError, match="sampling"):
        RLConfig(keyframes="anywhere")
