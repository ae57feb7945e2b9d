"""RL in imagination runs unchanged on the generative (flow) world model."""

import json

from gymnast.cli import main

from rl_helpers import JUDGE, POLICY


def test_rl_debug_preset_imagines_with_a_flow_world_model(rl_dataset, tmp_path):
    wm, out = tmp_path / "wm", tmp_path / "run"
    main(["train-wm", "--backend", "flow", "--preset", "debug", "--data", str(rl_dataset), "--out", str(wm)])
    main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(wm), "--reward", f"judge:{JUDGE}",
          "--out", str(out), "--data", str(rl_dataset), "--preset", "debug", "--watch-every", "0"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env"] == "imagined" and summary["steps"] == 2 and summary["real_interactions"] == 0
    assert (out / "checkpoints" / "000002" / "model.safetensors").exists()
