"""The committed models the RL tests run with: small, and real (trained on MT10)."""

from pathlib import Path

RESULTS = Path(__file__).resolve().parents[2] / "results"
POLICY = RESULTS / "sft" / "policy"
WORLD_MODEL = RESULTS / "world_model" / "wm"
JUDGE = RESULTS / "judge" / "one_camera" / "judge"
