"""How an equal real budget is sized for real-world GRPO, and refused where it cannot hold a group."""

from __future__ import annotations

import dataclasses

import pytest

from gymnast.experiment.config import EXPERIMENT_PRESETS, EqualBudgetConfig
from gymnast.experiment.equal_budget import budget_for


def test_real_grpo_takes_as_many_full_batches_as_the_budget_holds():
    full = EXPERIMENT_PRESETS["full"]  # MT10, 20 starts x 8 rollouts a step, 32 rollouts a task
    budget = budget_for(full.equal_budget, full)
    assert (budget.rollouts, budget.grpo_starts, budget.grpo_steps) == (320, 20, 2)
    odd = budget_for(EqualBudgetConfig(rollouts_per_task=7), full)  # 70 rollouts: one batch of 64, never more
    assert (odd.rollouts, odd.grpo_starts, odd.grpo_steps) == (70, 8, 1)


def test_a_budget_smaller_than_a_batch_takes_fewer_starts_in_one_step():
    debug = EXPERIMENT_PRESETS["debug"]  # reach alone, groups of 2
    budget = budget_for(EqualBudgetConfig(rollouts_per_task=3), debug)
    assert (budget.rollouts, budget.grpo_starts, budget.grpo_steps) == (3, 1, 1)


def test_a_budget_below_one_group_is_refused_naming_the_setting():
    full = EXPERIMENT_PRESETS["full"]
    with pytest.raises(ValueError, match=r"equal_budget.rollouts_per_task \(1\) x 1 tasks is 1 real rollouts"):
        dataclasses.replace(full, tasks="reach-v3", equal_budget=EqualBudgetConfig(rollouts_per_task=1))
    # 0 turns the comparison off
    assert dataclasses.replace(full, equal_budget=EqualBudgetConfig(rollouts_per_task=0)).equal_budget.rollouts_per_task == 0


def test_negative_settings_are_refused():
    with pytest.raises(ValueError, match="EqualBudgetConfig.wm_steps must be at least 0"):
        EqualBudgetConfig(wm_steps=-1)


@pytest.mark.slow
def test_iter_sft_imitates_real_successes_seen_by_the_policys_two_cameras(two_camera_demos, tmp_path):
    from gymnast.experiment.equal_budget import _iter_sft
    from gymnast.policy.sft import SFT_PRESETS, train_sft

    sft = dataclasses.replace(SFT_PRESETS["debug"], steps=2, checkpoint_every=2, demos_per_task=1,
                              cameras=("front", "gripper"))
    train_sft(two_camera_demos, tmp_path / "sft", sft, progress=False)
    config = dataclasses.replace(EXPERIMENT_PRESETS["debug"], sft=sft)
    config = dataclasses.replace(config, iter_sft=dataclasses.replace(config.iter_sft, steps=2))
    # The scripted episodes stand in for recorded rollouts: every one a real success, in both views.
    counts = _iter_sft(config, tmp_path / "sft", two_camera_demos, two_camera_demos, tmp_path / "iter_sft",
                       progress=False)
    assert counts["successes"] == 4 and counts["samples"] > 0
    assert (tmp_path / "iter_sft" / "checkpoints" / "last").exists()
