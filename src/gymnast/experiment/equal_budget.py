"""Equal real budgets: what a few dozen real rollouts per task are worth, spent three ways.

The seeds' premise is that real interactions are what a robot lab lacks. So the question the
headline asks last is not whether imagination beats the real world with unlimited rollouts, but
which use of the *same* small number of real rollouts improves the SFT policy most (WMPO's
comparison: 128 real rollouts; world-model practice 47.1%, GRPO on the same rollouts 33.2%):

- ``real_grpo``: GRPO in the real world, its rollouts as many as the budget's, in as many steps of
  the RL arms' batch as they fill (fresh scenes, the real-world arm's success reward, no refills);
- ``imagined``: the budget's rollouts of the SFT policy recorded in the real world; the world
  model and the judge refitted on them (as a Dyna round does); then practice in imagination for
  the RL arms' steps, rewarded by the refitted judge (WMPO's and World-Gymnast's recipe);
- ``iter_sft``: the SFT policy fine-tuned on the real successes among the same recorded rollouts,
  half of every batch from the demonstrations (Iter-SFT on real, not judged, successes).

Every real interaction that trains is counted: the real-world GRPO run's own, and the recorded
rollouts' actions for the other two. Evaluations measure and are counted apart. The recorded
rollouts are recorded again (the same seeds) when a run copied without them resumes before its
last arm has read them.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass
from pathlib import Path

from gymnast.experiment.config import EqualBudgetConfig, ExperimentConfig
from gymnast.experiment.stages import Stages
from gymnast.utils.checkpoint import has_checkpoint

logger = logging.getLogger(__name__)

EQUAL_BUDGET_ARMS = ("real_grpo", "imagined", "iter_sft")
"""The three uses of one real budget, as summary.json's ``equal_budget`` names them."""


@dataclass(frozen=True)
class Budget:
    """The real rollouts every arm may spend, and how real-world GRPO spends them.

    Attributes:
        rollouts: real rollouts in all (per task x tasks).
        grpo_starts: start states per GRPO step (the RL arms' unless the budget is smaller).
        grpo_steps: GRPO steps, so that steps x starts x group size <= rollouts.
    """

    rollouts: int
    grpo_starts: int
    grpo_steps: int


def budget_for(settings: EqualBudgetConfig, config: ExperimentConfig) -> Budget:
    """The budget of `settings` on `config`'s tasks, and the real-world GRPO run that fits it (the
    experiment's settings have checked that it holds at least one group)."""
    from gymnast.envs.tasks import resolve_tasks

    rollouts = settings.rollouts_per_task * len(resolve_tasks(config.tasks))
    group = config.rl.group_size
    starts = min(config.rl.starts_per_step, rollouts // group)
    return Budget(rollouts, starts, rollouts // (starts * group))


def train_equal_budget(stages: Stages, config: ExperimentConfig, out: Path, sft: Path, wm: Path, judge: Path,
                       data: Path, progress: bool = True) -> dict[str, Path]:
    """Runs the three arms in ``out`` (each a stage of `stages`); returns each arm's final policy run.

    The stage records say what each arm spent: ``real_interactions`` (training) besides the runs' own.
    """
    budget = budget_for(config.equal_budget, config)
    rollouts = out / "rollouts"
    record = functools.partial(_record, sft, config, rollouts, progress)
    stages.restore_dataset("equal_budget_rollouts", rollouts, record,
                           stages.pending(["equal_budget_imagined", "equal_budget_iter_sft"]),
                           "the equal budget's real rollouts")
    stages.run("equal_budget_rollouts", record, rollouts)
    recorded = stages.record("equal_budget_rollouts")["real_interactions"]
    arms = {"real_grpo": out / "real_grpo", "imagined": out / "imagined" / "rl", "iter_sft": out / "iter_sft"}
    stages.run("equal_budget_real_grpo", lambda: _real_grpo(config, budget, sft, data, arms["real_grpo"], progress),
               arms["real_grpo"])
    stages.run("equal_budget_imagined",
               lambda: _imagined(config, sft, wm, judge, data, rollouts, out / "imagined", progress) | {
                   "real_interactions": recorded}, arms["imagined"])
    stages.run("equal_budget_iter_sft",
               lambda: _iter_sft(config, sft, data, rollouts, arms["iter_sft"], progress) | {
                   "real_interactions": recorded}, arms["iter_sft"])
    return arms


def _record(sft: Path, config: ExperimentConfig, out: Path, progress: bool) -> dict:
    """The SFT policy's budget of real rollouts, sampled as RL samples them, on fresh data seeds."""
    from gymnast.eval.record import record_real_rollouts

    return record_real_rollouts(sft, config.tasks, config.equal_budget.rollouts_per_task, config.equal_budget.first_seed,
                                config.rl.temperature, config.rl.evaluation_horizon, config.workers, config.runner, out,
                                progress)


def _real_grpo(config: ExperimentConfig, budget: Budget, sft: Path, data: Path, out: Path, progress: bool) -> dict:
    """GRPO in the real world on as many rollouts as the budget holds, in the RL arms' batches."""
    from gymnast.envs.kinds import REAL
    from gymnast.experiment.arms import arm
    from gymnast.reward.spec import RewardSpec
    from gymnast.rl.config import RLRun
    from gymnast.rl.train import train_rl

    # No refills of dropped groups: each would spend rollouts outside the budget.
    settings = dataclasses.replace(config.rl, steps=budget.grpo_steps, starts_per_step=budget.grpo_starts,
                                   max_rounds=1, fresh_scenes=True, watch_every=0, eval_every=budget.grpo_steps)
    run = RLRun(str(sft), REAL, RewardSpec(arm("rl_real").reward), data=str(data))
    summary = train_rl(run, out, settings, resume=has_checkpoint(out), progress=progress)
    summary.pop("curve")
    return summary


def _imagined(config: ExperimentConfig, sft: Path, wm: Path, judge: Path, data: Path, rollouts: Path, out: Path,
              progress: bool) -> dict:
    """The world model and the judge refitted on the recorded rollouts, then the RL arms' practice
    in imagination on them (the judge's reward, the dataset's starts)."""
    from gymnast.envs.kinds import IMAGINED
    from gymnast.experiment.dyna import fine_tune_judge, fine_tune_world_model
    from gymnast.reward.spec import RewardSpec
    from gymnast.rl.config import RLRun
    from gymnast.rl.train import train_rl

    stages = Stages(out)
    settings = config.equal_budget
    new_wm, new_judge = out / "world_model", out / "judge"
    stages.run("world_model", lambda: fine_tune_world_model(wm, wm, [rollouts], settings.wm_steps, new_wm, progress),
               new_wm)
    stages.run("judge", lambda: fine_tune_judge(judge, judge, new_wm, [rollouts], settings.judge_steps, new_judge,
                                                progress), new_judge)
    run = RLRun(str(sft), IMAGINED, RewardSpec.judge(str(new_judge)), wm=str(new_wm), data=str(data))
    # The experiment evaluates the final policy in the real world: the run's own real evaluations
    # along the way would only repeat it.
    rl = dataclasses.replace(config.rl, fresh_scenes=False, real_eval=False, eval_every=config.rl.steps)
    target = out / "rl"
    summary = train_rl(run, target, rl, resume=has_checkpoint(target), progress=progress)
    summary.pop("curve")
    return summary


def _iter_sft(config: ExperimentConfig, sft: Path, data: Path, rollouts: Path, out: Path, progress: bool) -> dict:
    """The SFT policy fine-tuned on the recorded rollouts' real successes, 1:1 with the demonstrations."""
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.experiment.iter_sft import fine_tune_on_successes
    from gymnast.policy.load import load_policy
    from gymnast.policy.sft import load_demos

    policy = load_policy(sft)
    # The rollouts were recorded in the views the policy acts on: read side by side, as it sees them.
    dataset = EpisodeDataset(rollouts, cameras=policy.config.env_cameras)
    successes = [i for i, info in enumerate(dataset.episodes) if info.success]
    samples = load_demos(dataset, successes, policy.chunk_size) if successes else None
    if samples is None:
        logger.warning("equal budget: none of the %d recorded rollouts succeeded; Iter-SFT fine-tunes on the "
                       "demonstrations alone", len(dataset))
    fine_tune_on_successes(sft, data, samples, out, config, progress)
    return {"successes": len(successes), "samples": 0 if samples is None else len(samples.images)}
