"""`gymnast imagination` and `gymnast rl-signal` measure a LeRobot policy (``--policy lerobot:PATH``)
as they measure gymnast's own: its imagined rollouts against their real replays."""

import json
from pathlib import Path

from gymnast.cli import main

RESULTS = Path(__file__).resolve().parents[2] / "results"
WORLD_MODEL = RESULTS / "world_model" / "wm"
JUDGE = RESULTS / "judge" / "judge"


def test_imagination_replays_a_lerobot_policys_imagined_rollouts_for_real(lerobot_act, tmp_path):
    out = tmp_path / "imagination"
    main(["imagination", "--policy", f"lerobot:{lerobot_act}", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--tasks", "reach-v3", "--episodes", "1", "--horizon", "10", "--videos", "0", "--out", str(out)])
    report = json.loads((out / "imagination.json").read_text())
    assert report["settings"]["policy"] == f"lerobot:{lerobot_act}" and report["overall"]["episodes"] == 1


def test_rl_signal_measures_a_lerobot_policys_imagined_advantages_against_real_replays(lerobot_act, tmp_path):
    out = tmp_path / "signal"
    main(["rl-signal", "--policy", f"lerobot:{lerobot_act}", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--out", str(out), "--tasks", "reach-v3", "--starts-per-task", "1", "--group-size", "2", "--horizons", "10",
          "--batch", "2", "--workers", "1"])
    report = json.loads((out / "signal.json").read_text())
    assert len(report["rollouts"]) == 2 and report["interactions"] == 2 * 10  # each imagined rollout replayed for real
