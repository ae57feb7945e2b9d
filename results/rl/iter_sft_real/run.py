"""The equal-budget comparison's Iter-SFT arm alone, at the full preset's budget (32 real rollouts
per task): the SFT policy's rollouts recorded in the real world, the real successes imitated 1:1
with the demonstrations, by the experiment's own two steps. Run from the repository root:

    python results/rl/iter_sft_real/run.py runs/iter_sft_real
    gymnast eval --policy runs/iter_sft_real/policy --tasks mt10 --episodes 50 --videos-per-task 0 \
        --out results/rl/iter_sft_real/eval.json
"""

import json
import sys
from pathlib import Path

from gymnast.experiment.config import EXPERIMENT_PRESETS
from gymnast.experiment.equal_budget import _iter_sft, _record


def main(out: Path, policy: Path = Path("results/sft/policy"), data: Path = Path("data/mt10")) -> None:
    config = EXPERIMENT_PRESETS["full"]  # MT10; iter_sft: 400 steps at lr 1e-4; rl.temperature 1.0; 2 workers
    recorded = _record(policy, config, out / "rollouts", progress=True)
    used = _iter_sft(config, policy, data, out / "rollouts", out / "policy", progress=True)
    (out / "recorded.json").write_text(json.dumps(recorded | {"successes_used": used["successes"]}))


if __name__ == "__main__":  # the simulator's worker processes import this file again
    main(Path(sys.argv[1]))
