"""The headline's goals, each met only where the figures show it.

An arm beats another only where their 95% Wilson intervals say so: equal point estimates, or a lead
inside overlapping intervals, is no evidence at a small evaluation.
"""

from __future__ import annotations

from gymnast.experiment.arms import WM_ARMS

GOAL_OVER_SFT = 2.0
"""World-Gymnast's claim we test: world-model RL at least doubles SFT's real success."""
GOAL_WORLDGYM_R = 0.9
"""The WorldGym correlation we aim for (World-Gymnast reports 0.78)."""
GOAL_WATCH_FALSE_SUCCESS = 0.1
"""At most this share of a world-model arm's judged successes may fail when replayed for real."""
GOAL_DYNA_SHARE = 0.1
"""Dyna should match RL in the real world with at most this share of its real interactions."""


def experiment_goals(arms: dict[str, dict], weak: dict | None, worldgym_r: float | None,
                     watch_false_success: dict[str, float | None], equal_budget: dict | None = None) -> dict:
    """summary.json's ``goals``, each True only where the figures show it.

    Args:
        arms: summary.json's ``arms`` (each with ``success``, ``ci_low``, ``ci_high``, ``real_interactions``).
        weak: ``weak_tasks`` (None: the experiment has none).
        worldgym_r: WorldGym's Pearson r (None: undefined).
        watch_false_success: each world-model arm's judged successes that failed for real.
        equal_budget: ``equal_budget`` (None: not run).
    """
    return {
        "rl_real_beats_sft": above(arms["rl_real"], arms["sft"]),
        "wm_rl_beats_sft": above(arms["rl_wm_judge"], arms["sft"]),
        "wm_rl_at_least_2x_sft": _doubles_separately(arms["rl_wm_judge"], arms["sft"]),
        "wm_rl_beats_sim_rl": above(arms["rl_wm_judge"], arms["rl_sim"]),
        "any_wm_arm_beats_sft": any(above(arms[name], arms["sft"]) for name in WM_ARMS if name in arms),
        "worldgym_r_at_least_0.9": worldgym_r is not None and worldgym_r >= GOAL_WORLDGYM_R,
        "wm_rl_2x_sft_on_weak_tasks": _doubles_separately(weak["arms"]["rl_wm_judge"], weak["arms"]["sft"]) if weak else None,
        "dyna_reaches_real_rl_with_10pct": _dyna_goal(arms),
        "watch_false_success_at_most_10pct": {name: value is not None and value <= GOAL_WATCH_FALSE_SUCCESS
                                              for name, value in watch_false_success.items()},
        "imagined_beats_real_grpo_at_equal_budget": (above(equal_budget["imagined"], equal_budget["real_grpo"])
                                                     if equal_budget else None),
    }


def above(arm_row: dict, other: dict) -> bool:
    """Better than `other` with 95% intervals that do not overlap."""
    return arm_row["ci_low"] > other["ci_high"]


def _doubles_separately(arm_row: dict, sft: dict) -> bool:
    """At least twice SFT's success, with 95% intervals that do not overlap."""
    return arm_row["success"] >= GOAL_OVER_SFT * sft["success"] and above(arm_row, sft)


def _dyna_goal(arms: dict[str, dict]) -> bool | None:
    """Dyna matches RL in the real world with at most 10% of its real interactions for training:
    it learned (above SFT, intervals apart), and RL in the real world is not above it (intervals
    apart). Where no arm learned, every arm "matches" every other, which says nothing."""
    if "dyna" not in arms:
        return None
    dyna, real = arms["dyna"], arms["rl_real"]
    return (above(dyna, arms["sft"]) and not above(real, dyna)
            and dyna["real_interactions"] <= GOAL_DYNA_SHARE * real["real_interactions"])
