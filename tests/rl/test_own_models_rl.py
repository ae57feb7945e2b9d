"""RL in imagination with a world model and a policy of one's own (the example package
examples/tiny_video_wm), with no change to gymnast: loaded by entry point and by python path, the
world model offloaded around every policy update, the trained policy saved by its factory."""

import json

from gymnast.cli import main
from gymnast.policy.load import load_policy
from tiny_video_wm.gymnast_plugin import TinyVideoWorldModel
from tiny_video_wm.policy import TinyPolicy

from rl_helpers import JUDGE


def test_rl_practises_an_own_policy_in_an_own_video_diffusion_model(rl_dataset, tmp_path, monkeypatch):
    calls = []
    for hook in ("offload", "onload"):
        original = getattr(TinyVideoWorldModel, hook)
        monkeypatch.setattr(TinyVideoWorldModel, hook, lambda self, hook=hook, original=original: (calls.append(hook),
                                                                                                 original(self))[1])
    out = tmp_path / "run"
    main(["rl", "--policy", "python:tiny_video_wm.policy:load_policy", "--env", "imagined", "--wm", "plugin:tiny-video",
          "--reward", f"judge:{JUDGE}", "--data", str(rl_dataset), "--out", str(out), "--preset", "debug",
          "--watch-every", "0", "--no-real-eval"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env"] == "imagined" and summary["wm"] == "plugin:tiny-video" and summary["steps"] == 2
    assert calls and calls == ["offload", "onload"] * (len(calls) // 2)  # around each update, in pairs
    saved = json.loads((out / "checkpoints" / "000002" / "config.json").read_text())["model"]
    assert saved == {"plugin": {"source": "python:tiny_video_wm.policy:load_policy", "spec": None}}
    assert isinstance(load_policy(out), TinyPolicy)  # rebuilt by its factory, the run's weights loaded into it
