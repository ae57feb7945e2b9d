"""report.md: the experiment's tables and the evidence behind them, in words a reader can check.

Every sentence is computed from summary.json; nothing here is written in advance of the numbers.
"""

from __future__ import annotations

from gymnast.experiment.dyna_report import dyna_table
from gymnast.experiment.formatting import ci, number, pct, ratio, wall_time
from gymnast.experiment.report.goals import GOAL_DYNA_SHARE, GOAL_OVER_SFT
from gymnast.experiment.new_scenes import table as practice_table
from gymnast.experiment.report.evidence import evidence_section, imagination_section, signal_section


def _arms_table(summary: dict) -> list[str]:
    lines = ["| arm | real success | 95% CI | real interactions (training) | real interactions (evaluations, watch) | wall time |",
             "|---|---|---|---|---|---|"]
    for row in summary["arms"].values():
        lines.append(f"| {row['title']} | **{pct(row['success'])}** | {ci(row)} | {row['real_interactions']:,} | "
                     f"{row['eval_real_interactions'] + row['watch_real_interactions']:,} | {wall_time(row)} |")
    return lines


def verdict_lines(summary: dict) -> list[str]:
    """The result in sentences, each goal called met only where the intervals say so (markdown)."""
    arms, goals = summary["arms"], summary["goals"]
    sft, wm, sim, verified, real = (arms[name] for name in ("sft", "rl_wm_judge", "rl_sim", "rl_wm_verified", "rl_real"))
    met = {True: "met", False: "not met"}
    learned = goals.get("rl_real_beats_sft")  # None in experiments from before the goal
    return [
        (f"- World-model RL with the judge (World-Gymnast) reached {pct(wm['success'])} against SFT's "
         f"{pct(sft['success'])}: {ratio(summary['wm_rl_over_sft'])} SFT ({_significance(wm, sft)}). "
         f"Goal of at least 2x: **{goal_in_words(goals['wm_rl_at_least_2x_sft'], wm['success'] >= GOAL_OVER_SFT * sft['success'])}**."),
        (f"- Against RL in the software simulator ({pct(sim['success'])}): {ratio(summary['wm_rl_over_sim_rl'])} "
         f"({_significance(wm, sim)}). Goal of beating it: "
         f"**{goal_in_words(goals['wm_rl_beats_sim_rl'], wm['success'] > sim['success'])}**."),
        (f"- World-model RL with the verified reward (VLA-RFT) reached {pct(verified['success'])}: "
         f"{ratio(summary['wm_rl_verified_over_sft'])} SFT ({_significance(verified, sft)})."),
        *_grounded_verdict(arms),
        (f"- RL in the real world, which spent {real['real_interactions']:,} real interactions on training, "
         f"reached {pct(real['success'])} ({_significance(real, sft)} with SFT)"
         + ("." if learned is None else
            f". Goal of beating SFT (the recipe learns): **{goal_in_words(learned, real['success'] > sft['success'])}**.")),
        (f"- WorldGym: Pearson r = {number(summary['worldgym_pearson'])}, Spearman = {number(summary['worldgym_spearman'])} over "
         f"{len(summary['worldgym'])} policies. Goal r >= 0.9: **{met[goals['worldgym_r_at_least_0.9']]}**."),
        *_weak_tasks_verdict(summary), *_dyna_verdict(summary), *_equal_budget_verdict(summary), *_watch_verdict(summary),
        *_ladder_ends_verdict(summary),
    ]


def _ladder_ends_verdict(summary: dict) -> list[str]:
    """The learning ladder's two ends beside SFT (docs/rl.md "Where learning dies"): R0, RL in the
    real world on the simulator's success, and R4, RL in imagination on the judge's verdict, with
    how often R4's verdict held for real at its last watch; one sentence where the intervals cannot
    tell them apart, rather than a row of identical verdicts."""
    arms = summary["arms"]
    sft, r0, r4 = arms["sft"], arms["rl_real"], arms["rl_wm_judge"]
    watched = [row for row in summary.get("watch", {}).get("rl_wm_judge", []) if row.get("agreement") is not None]
    held = (f"; at its last watch the judge's imagined verdicts held for real in {pct(watched[-1]['agreement'])} of the "
            f"replays" if watched else "")
    line = (f"- The learning ladder's two ends: R0, reality (RL in the real world on the simulator's success), "
            f"{pct(r0['success'])} {ci(r0)}; R4, imagination (the judge on imagined video), {pct(r4['success'])} "
            f"{ci(r4)}{held}; SFT {pct(sft['success'])} {ci(sft)}.")
    apart = {name: not _overlap(arm, sft) for name, arm in (("r0", r0), ("r4", r4))}
    if not any(apart.values()) and _overlap(r0, r4):
        return [line + " At this size their 95% intervals overlap, so the ends cannot be told apart; `gymnast ladder "
                "--preset full` runs every rung between them (docs/rl.md)."]
    if apart["r0"] and not apart["r4"]:
        return [line + " Reality teaches and imagination does not: the rungs between them (`gymnast ladder`) say "
                "which part of imagination loses it."]
    return [line]


def _short_title(summary: dict, name: str) -> str:
    """An arm's title without its parenthesis, for the report's sentences."""
    return summary["arms"][name]["title"].split(" (")[0]


def _equal_time_section(summary: dict) -> list[str]:
    """The RL arms at equal wall-clock (`gymnast.experiment.report.equal_time`): the steps each had time
    for, and RL in the real world's success by the time each other arm had finished."""
    timing = summary.get("equal_wall_clock")  # None in experiments from before the readout
    if not timing or not timing["arms"]:
        return []
    reference = timing["reference"]
    real_title = _short_title(summary, reference["arm"])
    lines = ["## At equal wall-clock", "",
             (f"Every RL arm took {summary['rl_steps']} steps; their minutes differ. {real_title} trained its "
              f"{reference['steps']} steps in {reference['train_s'] / 60:.1f} min (training only: rollouts and updates, "
              "without the evaluations and the watch). Beside each other arm: how far it had got in that arm's "
              "time, with its last evaluation by then, and how many of that arm's steps its own time would have "
              "paid for (a projection at the arm's mean step time, not a run)."), "",
             f"| arm | steps | training | {real_title}'s steps in that time | its success by then | steps {real_title}'s time pays for |",
             "|---|---|---|---|---|---|"]
    for name, row in timing["arms"].items():
        at_time = row["reference_at_that_time"]
        success = "-" if at_time is None else f"{pct(at_time['success'])} {ci(at_time)} (step {at_time['step']})"
        lines.append(f"| {summary['arms'][name]['title']} | {row['steps']} | {row['train_s'] / 60:.1f} min | "
                     f"{row['reference_steps_in_that_time']} of {reference['steps']} | {success} | "
                     f"{row['steps_in_reference_time']} |")
    return [*lines, ""]


def _grounded_verdict(arms: dict) -> list[str]:
    grounded, sft = arms.get("rl_wm_state"), arms["sft"]  # None in experiments from before the arm
    if grounded is None:
        return []
    return [(f"- World-model RL with the state model's reward (grounded) reached {pct(grounded['success'])} "
             f"({_significance(grounded, sft)} with SFT).")]


def _task_names(weak: dict) -> str:
    return ", ".join(task.removesuffix("-v3") for task in weak["tasks"])


def _pooled(summary: dict, pooled: dict, intervals: bool = False) -> str:
    """Each arm's success pooled over the weak tasks, in words (with its interval)."""
    return ", ".join(f"{_short_title(summary, name)} {pct(row['success'])}" + (f" {ci(row)}" if intervals else "")
                     for name, row in pooled.items())


def _weak_tasks_verdict(summary: dict) -> list[str]:
    weak = summary.get("weak_tasks")  # None in experiments from before the field, or without weak tasks
    if not weak:
        return []
    pooled = weak["arms"]
    ahead = pooled["rl_wm_judge"]["success"] >= GOAL_OVER_SFT * pooled["sft"]["success"]
    return [(f"- On the weak tasks ({_task_names(weak)}; "
             f"{pooled['sft']['episodes']} episodes per arm): {_pooled(summary, pooled)}. World-model RL (judge) at "
             f"least 2x SFT with separate intervals: **{goal_in_words(summary['goals']['wm_rl_2x_sft_on_weak_tasks'], ahead)}**.")]


def _dyna_verdict(summary: dict) -> list[str]:
    arms = summary["arms"]
    if "dyna" not in arms:
        return []
    dyna, real = arms["dyna"], arms["rl_real"]
    share = dyna["real_interactions"] / real["real_interactions"] if real["real_interactions"] else None
    ahead = (dyna["success"] >= real["success"] and dyna["success"] > arms["sft"]["success"]
             and share is not None and share <= GOAL_DYNA_SHARE)
    return [(f"- Dyna reached {pct(dyna['success'])} with {dyna['real_interactions']:,} real interactions for training "
             f"({pct(share)} of RL in the real world's {real['real_interactions']:,}, which reached {pct(real['success'])}; "
             f"{_significance(dyna, real)}). Goal of matching it with at most 10% of its interactions, having learned "
             f"(above SFT, intervals apart): **{goal_in_words(summary['goals']['dyna_reaches_real_rl_with_10pct'], ahead)}**.")]


EQUAL_BUDGET_TITLES = {"real_grpo": "GRPO in the real world", "imagined": "world model and judge refitted, then practice in imagination",
                       "iter_sft": "Iter-SFT on their real successes"}


def _equal_budget_verdict(summary: dict) -> list[str]:
    budget = summary.get("equal_budget")  # None in experiments without the comparison
    if not budget:
        return []
    imagined, grpo = budget["imagined"], budget["real_grpo"]
    rows = "; ".join(f"{EQUAL_BUDGET_TITLES[name]} {pct(budget[name]['success'])} "
                     f"({budget[name]['real_interactions']:,} real interactions)" for name in EQUAL_BUDGET_TITLES)
    met = summary["goals"]["imagined_beats_real_grpo_at_equal_budget"]
    per_task = summary["equal_budget_setup"]["rollouts_per_task"]
    return [(f"- Equal real budgets, {per_task} real rollouts per task spent three ways: {rows}. "
             f"Practice in imagination above GRPO on the same real budget, intervals apart: "
             f"**{goal_in_words(met, imagined['success'] > grpo['success'])}**.")]


def _equal_budget_section(summary: dict) -> list[str]:
    """The equal-budget arms beside SFT: success, interval and the real interactions each spent."""
    budget, setup = summary.get("equal_budget"), summary.get("equal_budget_setup")
    if not budget:
        return []
    sft = summary["arms"]["sft"]
    recorded = setup["recorded"]
    lines = ["## Equal real budgets", "",
             (f"{setup['rollouts_per_task']} real rollouts per task: the SFT policy's, recorded once ({recorded['episodes']} "
              f"episodes, {recorded['successes']} successes, {recorded['real_interactions']:,} real interactions) for the "
              f"world model's refit and for Iter-SFT; GRPO in the real world spends as many of its own in "
              f"{setup['real_grpo_steps']} step(s); practice in imagination takes {setup['imagined_rl_steps']} steps."), "",
             "| arm | success | 95% CI | real interactions for training |", "|---|---|---|---|",
             f"| SFT | {pct(sft['success'])} | [{pct(sft['ci_low'])}, {pct(sft['ci_high'])}] | 0 |"]
    for name, title in EQUAL_BUDGET_TITLES.items():
        row = budget[name]
        lines.append(f"| {title} | {pct(row['success'])} | [{pct(row['ci_low'])}, {pct(row['ci_high'])}] | "
                     f"{row['real_interactions']:,} |")
    return [*lines, ""]


def _watch_verdict(summary: dict) -> list[str]:
    judged = {name: value for name, value in summary.get("watch_false_success", {}).items() if value is not None}
    if not judged:
        return []
    rows = ", ".join(f"{_short_title(summary, name)} {pct(value)}" for name, value in judged.items())
    held = all(summary["goals"]["watch_false_success_at_most_10pct"][name] for name in judged)
    line = (f"- Reward-hacking watch at the end of training, judged successes that failed when replayed for real: {rows}. "
            f"Goal of at most 10%: **{'met' if held else 'not met'}**.")
    return [line + ("" if held else _before_practice(summary, max(judged.values())))]


def _before_practice(summary: dict, worst: float) -> str:
    """What stands in the way of the watch's goal, in numbers: the same share on the SFT policy's own
    imagined rollouts before any practice (the imagination stage). Where it was as high, the false
    successes were the world model's and the judge's from the start, not a hack RL learned."""
    imagination = summary.get("imagination") or {}
    before = imagination.get("false_success")
    if before is None:
        return ""
    cause = ("they come from the world model and the judge, not from a hack practice learned" if worst <= before else
             f"practice added {100 * (worst - before):.1f} points to them")
    return (f" Before any practice, {pct(before)} of the SFT policy's imagined successes already failed when its "
            f"actions were replayed for real (the imagination stage, {imagination['episodes']} episodes): {cause}.")


def goal_in_words(met: bool, ahead: bool) -> str:
    """A comparison goal in words: met only when the 95% intervals say so; a lead they do not
    confirm is "not significant at this size" (more evaluation episodes may settle it)."""
    if met:
        return "met"
    return "not significant at this size" if ahead else "not met"


def _overlap(a: dict, b: dict) -> bool:
    """Whether the 95% intervals of two rows overlap."""
    return a["ci_low"] <= b["ci_high"] and b["ci_low"] <= a["ci_high"]


def _significance(a: dict, b: dict) -> str:
    if _overlap(a, b):
        return "the 95% intervals overlap: no significant difference"
    return "the 95% intervals do not overlap"


def _per_task_table(summary: dict) -> list[str]:
    arms = summary["arms"]
    tasks = list(next(iter(arms.values()))["per_task"])
    lines = ["| task | " + " | ".join(name for name in arms) + " |", "|---|" + "---|" * len(arms)]
    for task in tasks:
        lines.append(f"| {task} | " + " | ".join(pct(row["per_task"][task]["success"]) for row in arms.values()) + " |")
    return lines


def _robustness_tables(summary: dict) -> list[str]:
    own = summary.get("language_sentences")  # None in experiments from before the sentences file
    wording = f"your sentences ({own})" if own else "held-out paraphrases"
    lines = [f"| policy | no perturbation | minor (2.5 cm) | major (5 cm) | trained instructions | {wording} |",
             "|---|---|---|---|---|---|"]
    for name, row in summary["robustness"].items():
        language = summary["language"][name]
        lines.append(f"| {summary['arms'][name]['title']} | {pct(row['none']['success'])} | "
                     f"{pct(row['minor']['success'])} {ci(row['minor'])} | {pct(row['major']['success'])} {ci(row['major'])} | "
                     f"{pct(language['train']['success'])} | {pct(language['heldout']['success'])} {ci(language['heldout'])} |")
    episodes = next(iter(summary["robustness"].values()))["minor"]["episodes"]
    lines += ["", (f"Perturbed and held-out-instruction evaluations use {episodes} episodes in all per policy; "
              "the unperturbed column is the main evaluation.")]
    return lines


def _worldgym_table(summary: dict) -> list[str]:
    lines = ["| policy | imagined (judged) success | real success |", "|---|---|---|"]
    for row in summary["worldgym"]:
        lines.append(f"| {row['policy']} | {pct(row['imagined'])} ({row['imagined_episodes']} ep.) | "
                     f"{pct(row['real'])} ({row['real_episodes']} ep.) |")
    return lines


def _dyna_section(summary: dict, plots: dict[str, str]) -> list[str]:
    """Dyna's rounds beside RL in the real world: real success against real interactions spent."""
    dyna = summary.get("dyna")  # None in experiments without the Dyna arm
    if not dyna:
        return []
    lines = ["## Dyna against RL in the real world", "", dyna_table(dyna), ""]
    fprs = [row["judge_fpr_on_rollouts"] for row in dyna["rounds"] if row.get("judge_fpr_on_rollouts") is not None]
    if fprs:
        lines += [(f"Before fine-tuning on them, the judge passed {', '.join(pct(v) for v in fprs)} of the failures among "
                   "the real rollouts recorded between rounds (its false-positive rate on whole failures)."), ""]
    return [*lines, f"![Dyna against RL in the real world]({plots['dyna']})", ""]


def _new_scenes_section(summary: dict) -> list[str]:
    """Test-time practice: each new scene's real success before and after practising on it in imagination."""
    practice = summary.get("new_scenes")  # None where the preset leaves it out
    if not practice:
        return []
    return ["## Test-time practice on new scenes", "",
            ("The SFT policy practised in imagination from each new scene's first frame (an evaluation seed, in no "
             "dataset), rewarded by the judge, then acted on that scene in the real world."), "",
            *practice_table(practice["scenes"], practice["totals"])]


def _sft_regime(summary: dict) -> str:
    """How many demonstrations the SFT policy imitated (absent in older summaries and for policies
    that saved none)."""
    demos = summary.get("sft_demonstrations")
    if not demos:
        return ""
    return (f" (behaviour-cloned on {demos['per_task']} expert demonstrations per task, {demos['episodes']} in all, "
            "while the world model and the judge learn from the whole dataset)")


TITLE = "Headline experiment: practising in a learned world model vs. SFT and a software simulator"


def _introduction(summary: dict) -> str:
    return (f"Tasks: {summary['tasks']}. Every arm starts from the same SFT policy{_sft_regime(summary)}; the RL arms take "
            f"{summary['rl_steps']} RL steps of {summary['rollouts_per_step']} rollouts each. Every policy is measured in the "
            f"real world on {summary['eval_episodes_per_task']} evaluation seeds per task (never recorded in any dataset), "
            "greedy, with 95% Wilson intervals.")


def _interactions(summary: dict) -> str:
    dataset = summary["dataset"]
    # None: an exported experiment under way, its dataset left out and not yet counted by a report.
    counted = ("not here to count: the experiment was exported without it" if dataset is None else
               f"{dataset['episodes']} episodes, {dataset['real_interactions']:,} real interactions")
    return (f"Real interactions are counted beyond the shared dataset ({counted}), which every arm uses. Evaluations "
            "and the reward-hacking watch also act in the real world; they are counted apart.")


def _weak_tasks_so_far(summary: dict) -> list[str]:
    weak = summary.get("weak_tasks")
    if not weak or not weak["arms"]:
        return []
    return [f"On the weak tasks ({_task_names(weak)}): {_pooled(summary, weak['arms'], intervals=True)}.", ""]


def partial_report_markdown(summary: dict) -> str:
    """The report of an experiment under way: the arms evaluated so far and the measurements that ran,
    with the stages still to run; the verdicts, the comparisons and the plots wait for every stage."""
    to_run = summary["stages_to_run"]
    arms = [*_arms_table(summary), "", *_weak_tasks_so_far(summary)] if summary["arms"] else ["No arm evaluated yet.", ""]
    lines = [
        f"# {TITLE} (under way)", "", _introduction(summary), "",
        (f"**{len(to_run)} stages still to run** ({', '.join(f'`{name}`' for name in to_run)}): these are the figures of "
         "the stages finished so far. `gymnast experiment --out RUN --resume` runs the rest; the verdicts on the goals, "
         "the comparisons and the plots come with the last stage."), "",
        "## Arms evaluated so far", "", *arms, _interactions(summary), "",
        "## Imagination under the SFT policy: judged imagined outcomes vs the real world", "", *imagination_section(summary),
        "## Does practice in imagination point the right way?", "", *signal_section(summary),
        "## Evidence: where imagination and reality part", "", *evidence_section(summary),
    ]
    return "\n".join(lines) + "\n"


def report_markdown(summary: dict, plots: dict[str, str]) -> str:
    """The report, from summary.json's content and the plots' paths (relative to the report)."""
    lines = [
        f"# {TITLE}", "", _introduction(summary), "",
        "## Result", "", *_arms_table(summary), "", *verdict_lines(summary), "", _interactions(summary), "",
        f"![per-task success]({plots['per_task']})", "",
        f"![learning curves]({plots['curves']})", "",
        "## Per task", "", *_per_task_table(summary), "",
        *_equal_time_section(summary),
        *_dyna_section(summary, plots),
        *_equal_budget_section(summary),
        *_new_scenes_section(summary),
        "## Robustness and language", "", *_robustness_tables(summary), "",
        "## WorldGym: does the world model rank policies like the real world?", "", *_worldgym_table(summary), "",
        f"![WorldGym]({plots['worldgym']})", "",
        "## Imagination under the SFT policy: judged imagined outcomes vs the real world", "", *imagination_section(summary),
        "## Does practice in imagination point the right way?", "", *signal_section(summary),
        "## Evidence: where imagination and reality part", "", *evidence_section(summary),
        "## Files", "",
        ("- `summary.json`: every figure above; `config.json`: the resolved settings; `stages/`: one record per stage "
        "with its wall time."),
        "- `eval/`: one report per evaluation (per-episode records, seeds) and the first episode of each task as video.",
        "- `imagination/`: the SFT policy's imagined rollouts against their real replays (imagination.json, imagination.md, videos).",
        "- `signal/`: GRPO groups in imagination against the real outcomes of the same actions (signal.json, signal.md).",
        "- `arms/<arm>/`: each arm's run (metrics.jsonl, TensorBoard, rollout videos with their rewards, summary.json).",
        "- `equal_budget/`: the recorded rollouts and the runs of the equal-budget comparison.",
        "- `new_scenes/`: one test-time practice run per new scene (metrics.jsonl, summary.json, video).",
    ]
    return "\n".join(lines) + "\n"
