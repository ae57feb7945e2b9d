"""The equal-budget comparison's Iter-SFT arm alone, at the full preset's budget (32 real rollouts
per task): the SFT policy's rollouts recorded in the real world, the real successes imitated 1:1
with the demonstrations. Run from the repository root:

    python results/rl/iter_sft_real/run.py runs/iter_sft_real
    gymnast eval --policy runs/iter_sft_real/policy --tasks mt10 --episodes 50 --videos-per-task 0 \
        --out results/rl/iter_sft_real/eval.json
"""

import json
import sys
from pathlib import Path

from gymnast.data.lerobot import EpisodeDataset
from gymnast.eval.record import record_real_rollouts
from gymnast.experiment.config import EXPERIMENT_PRESETS
from gymnast.experiment.iter_sft import fine_tune_on_successes
from gymnast.policy.load import load_policy
from gymnast.policy.sft import load_demos


def main(out: Path, policy: Path = Path("results/sft/policy"), data: Path = Path("data/mt10")) -> None:
    config = EXPERIMENT_PRESETS["full"]  # iter_sft: 400 steps at lr 1e-4; rl.temperature 1.0
    budget = config.equal_budget
    recorded = record_real_rollouts(policy, "mt10", budget.rollouts_per_task, budget.first_seed,
                                    config.rl.temperature, 150, 2, "local", out / "rollouts")
    dataset = EpisodeDataset(out / "rollouts")
    successes = [i for i, info in enumerate(dataset.episodes) if info.success]
    samples = load_demos(dataset, successes, load_policy(policy).chunk_size)
    fine_tune_on_successes(policy, data, samples, out / "policy", config)
    (out / "recorded.json").write_text(json.dumps(recorded | {"successes_used": len(successes)}))


if __name__ == "__main__":  # the simulator's worker processes import this file again
    main(Path(sys.argv[1]))
