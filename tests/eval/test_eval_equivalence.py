"""`gymnast eval` through the rollout engine gives the per-episode records it gave before it.

The records in eval_records_before_engine.json were written by `gymnast eval` when it still
stepped its episodes by hand (commit af35195), for the expert and the committed SFT policy, in the
real world and in the mild simulator with minor perturbations.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from gymnast.config import EnvConfig
from gymnast.eval.evaluate import EvalConfig, evaluate

BEFORE = json.loads((Path(__file__).parent / "eval_records_before_engine.json").read_text())
REPO = Path(__file__).parents[2]
POLICY = REPO / "results" / "sft" / "policy"


def _policy_is_the_recorded_one() -> bool:
    weights = POLICY / "model.safetensors"
    return weights.is_file() and hashlib.sha256(weights.read_bytes()).hexdigest() == BEFORE["policy_weights_sha256"]


@pytest.mark.slow
@pytest.mark.parametrize("key", sorted(BEFORE["records"]))
def test_eval_records_are_the_ones_recorded_before_the_rollout_engine(key: str, tmp_path: Path):
    policy, gap, perturb = key.split("|")
    if policy != "expert":
        if not _policy_is_the_recorded_one():
            pytest.skip(f"{POLICY} holds other weights than the records were made with")
        policy = str(REPO / policy)
    config = EvalConfig(tasks="reach-v3,drawer-open-v3", episodes=2, workers=1, videos_per_task=1, gap=gap,
                        perturb=perturb, env=EnvConfig(horizon=40))
    report = evaluate(policy, config, tmp_path / "report.json", progress=False)
    assert report["records"] == BEFORE["records"][key]
