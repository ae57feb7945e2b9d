"""The headline's goals are met only where the 95% intervals say so, and the report says which
leads its evaluation is too small to confirm."""

from __future__ import annotations

import json
from pathlib import Path

from gymnast.eval.stats import wilson_interval
from gymnast.experiment.arms import ARM_NAMES
from gymnast.experiment.report.goals import experiment_goals
from gymnast.experiment.report.write import format_table
from gymnast.experiment.report.text import goal_in_words

COMMITTED_HEADLINE = Path(__file__).resolve().parents[2] / "results" / "headline" / "summary.json"


def _row(successes: int, episodes: int, real_interactions: int = 0) -> dict:
    low, high = wilson_interval(successes, episodes)
    return {"success": successes / episodes, "ci_low": low, "ci_high": high, "real_interactions": real_interactions}


def _goals(rows: dict[str, dict]) -> dict:
    return experiment_goals(rows, None, 0.5, {"rl_wm_judge": 0.0})


def test_a_lead_inside_overlapping_intervals_meets_no_goal():
    # The demo's case: world-model RL 45% against 40% for the software simulator, 20 episodes each.
    rows = {name: _row(8, 20) for name in ARM_NAMES} | {"rl_wm_judge": _row(9, 20)}
    goals = _goals(rows)
    assert not goals["wm_rl_beats_sim_rl"] and not goals["wm_rl_beats_sft"] and not goals["any_wm_arm_beats_sft"]
    assert goal_in_words(goals["wm_rl_beats_sim_rl"], ahead=True) == "not significant at this size"
    assert goal_in_words(goals["wm_rl_beats_sim_rl"], ahead=False) == "not met"


def test_dyna_matches_nothing_where_no_arm_learned():
    # Every arm at 40%: Dyna "matches" RL in the real world with few interactions, yet nothing learned.
    rows = {name: _row(80, 200) for name in ARM_NAMES}
    rows["rl_real"]["real_interactions"], rows["dyna"]["real_interactions"] = 100_000, 5_000
    assert _goals(rows)["dyna_reaches_real_rl_with_10pct"] is False


def test_goals_separated_by_their_intervals_are_met():
    rows = {name: _row(80, 200) for name in ARM_NAMES}
    rows |= {"rl_real": _row(150, 200, 100_000), "rl_wm_judge": _row(170, 200), "dyna": _row(140, 200, 5_000)}
    goals = _goals(rows)
    assert goals["rl_real_beats_sft"] and goals["wm_rl_beats_sft"] and goals["wm_rl_beats_sim_rl"]
    assert goals["wm_rl_at_least_2x_sft"] and goals["dyna_reaches_real_rl_with_10pct"]
    assert goal_in_words(goals["wm_rl_beats_sft"], ahead=True) == "met"
    rows["dyna"]["real_interactions"] = 20_000  # 20% of the real-world arm's: too many
    assert not _goals(rows)["dyna_reaches_real_rl_with_10pct"]


def test_the_printed_table_says_a_lead_is_not_significant_at_this_size():
    # The committed headline's summary, with the demo's case: 45% against 40%, 20 episodes each.
    summary = json.loads(COMMITTED_HEADLINE.read_text())
    summary["arms"] = {name: row | _row(8, 20) for name, row in summary["arms"].items()}
    summary["arms"]["rl_wm_judge"] |= _row(9, 20)
    summary["goals"] = experiment_goals(summary["arms"], None, 0.5, summary["watch_false_success"])
    summary["weak_tasks"] = None
    text = format_table(summary)
    assert "Goal of beating it: not significant at this size." in text and "**" not in text
    assert "Goal of beating SFT (the recipe learns): not met." in text  # 40% against 40%


def test_imagination_beats_real_grpo_at_an_equal_budget_only_with_its_interval_apart():
    rows = {name: _row(80, 200) for name in ARM_NAMES}
    close = {"real_grpo": _row(80, 200, 9000), "imagined": _row(90, 200, 9000), "iter_sft": _row(85, 200, 9000)}
    assert experiment_goals(rows, None, 0.5, {}, close)["imagined_beats_real_grpo_at_equal_budget"] is False
    apart = close | {"imagined": _row(130, 200, 9000)}
    assert experiment_goals(rows, None, 0.5, {}, apart)["imagined_beats_real_grpo_at_equal_budget"] is True
    assert experiment_goals(rows, None, 0.5, {})["imagined_beats_real_grpo_at_equal_budget"] is None  # not run


def test_an_unmet_watch_is_set_against_imaginations_false_successes_before_practice():
    summary = json.loads(COMMITTED_HEADLINE.read_text())
    summary["imagination"] |= {"false_success": 0.62, "episodes": 100}
    for watched, says in ((0.57, "not from a hack practice learned"), (0.75, "practice added 13.0 points to them")):
        summary["watch_false_success"] = {"rl_wm_judge": watched}
        summary["goals"] = experiment_goals(summary["arms"], None, 0.5, summary["watch_false_success"])
        text = format_table(summary)
        assert "Before any practice, 62.0% of the SFT policy's imagined successes already failed" in text
        assert says in text
    summary["watch_false_success"] = {"rl_wm_judge": 0.05}  # met: nothing stands in the way
    summary["goals"] = experiment_goals(summary["arms"], None, 0.5, summary["watch_false_success"])
    assert "Before any practice" not in format_table(summary)


def test_the_report_reads_the_judges_ranking_apart_from_its_threshold_when_measured():
    from collections import defaultdict

    from gymnast.experiment.report.text import report_markdown

    plots = defaultdict(lambda: "plot.png")
    summary = json.loads(COMMITTED_HEADLINE.read_text())
    summary["judge"].pop("real_roc", None)  # measured before the readout existed: nothing said
    assert "(AUC)" not in report_markdown(summary, plots)
    summary["judge"]["real_roc"] = {"auc": 0.9876, "at_tpr": 0.95, "lowest_fpr": 0.0526}
    text = report_markdown(summary, plots)
    assert ("ranks a success above a failure 98.8% of the time (AUC); the best threshold for these very cases "
            "would pass at least 95.0% of the successes at FPR 0.05.") in text


def test_the_ladders_two_ends_are_one_sentence_where_the_demos_size_cannot_tell_them_apart():
    summary = json.loads(COMMITTED_HEADLINE.read_text())
    summary["arms"] = {name: row | _row(8, 20) for name, row in summary["arms"].items()}
    summary["goals"] = experiment_goals(summary["arms"], None, 0.5, summary["watch_false_success"])
    summary["weak_tasks"] = None
    text = format_table(summary)
    assert "R0, reality" in text and "R4, imagination" in text
    assert "cannot be told apart" in text and "Reality teaches" not in text
    # Reality apart from SFT, imagination not: the sentence points to the rungs between them.
    summary["arms"]["rl_real"] |= _row(19, 20)
    text = format_table(summary)
    assert "cannot be told apart" not in text and "Reality teaches and imagination does not" in text
