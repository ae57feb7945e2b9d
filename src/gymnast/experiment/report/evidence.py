"""report.md's evidence: imagination under the SFT policy against the real world, whether practice in
imagination points the right way, and where imagination and reality part (the world model, the judge,
the reward-hacking watch).

Every sentence is computed from summary.json; nothing here is written in advance of the numbers.
"""

from __future__ import annotations

from gymnast.experiment.arms import arm
from gymnast.experiment.formatting import ci, number, pct
from gymnast.world_model.metrics import measured_step


def _missing(summary: dict, stage: str) -> str:
    """Why a measuring stage's figures are absent: still to run, or an experiment older than the stage."""
    if stage in summary.get("stages_to_run", ()):
        return f"Not measured yet (the `{stage}` stage is still to run)."
    return f"Not measured in this experiment (it predates the `{stage}` stage)."


def imagination_section(summary: dict) -> list[str]:
    """The SFT policy's judged imagined rollouts against the same actions replayed in the real world."""
    figures = summary.get("imagination")
    if not figures:
        return [_missing(summary, "imagination"), ""]

    def rate(row: dict) -> str:
        return f"{pct(row['success'])} {ci(row)}"

    counts, judge = figures["confusion"], figures["judge_on_real"]
    return [
        (f"The SFT policy rolled out greedy in the world model from {figures['episodes']} evaluation scenes, each video "
         "judged by the learned judge, then the same actions replayed in the real world from the same scene."), "",
        "| imagined success (judged) | real replay of the same actions | SFT closed loop, real | agreement | "
        "false success | tp / fp / fn / tn | judge on the real videos (TPR / FPR) | PSNR at 8 / 32 steps (dB) |",
        "|---|---|---|---|---|---|---|---|",
        (f"| {rate(figures['imagined_success'])} | {rate(figures['replay_success'])} | {rate(figures['real_success'])} | "
         f"**{pct(figures['agreement'])}** | {pct(figures['false_success'])} | "
         f"{counts['tp']} / {counts['fp']} / {counts['fn']} / {counts['tn']} | "
         f"{pct(judge['tpr'])} / {pct(judge['fpr'])} | {number(figures['psnr_h8'])} / {number(figures['psnr_h32'])} |"), "",
        "Per task, PSNR per step and side-by-side videos: [imagination/imagination.md](imagination/imagination.md).", "",
    ]


def signal_section(summary: dict) -> list[str]:
    """Whether GRPO's update in imagination is the one the real outcomes of the same actions would
    give, over every task and over the weak ones."""
    figures = summary.get("signal")
    if not figures:
        return [_missing(summary, "signal"), ""]

    def rows(block: dict) -> list[str]:
        lines = []
        for name, key in (("the judge on imagined video (what World-Gymnast's arm trains on)", "imagined"),
                          ("the state model's reward head on the imagined states (the grounded arm's)", "imagined_state"),
                          ("the judge on the real replay's video (reference)", "real_video"),
                          ("the real world's dense reward (reference)", "real_dense")):
            if key not in block:  # experiments older than a readout
                continue
            figures_of = block[key]
            low, high = figures_of["correlation_ci_low"], figures_of["correlation_ci_high"]
            interval = "" if low is None else f" [{low:+.2f}, {high:+.2f}]"
            value = figures_of["advantage_correlation"]
            correlation = "-" if value is None else f"{value:+.2f}"
            lines.append(f"| {name} | **{correlation}**{interval} | {pct(figures_of['reinforced_real_success'])} / "
                         f"{pct(figures_of['discouraged_real_success'])} | {pct(figures_of['signal_groups'])} |")
        return lines

    header = ["| readout | advantage correlation [95% CI] | real success of reinforced / discouraged rollouts "
              "| groups ranked |", "|---|---|---|---|"]
    lines = [
        (f"{figures['rollouts']} rollouts of the SFT policy sampled in GRPO groups in the world model from the starts "
         f"the world-model arms practise from ({figures['horizon']} actions), scored, and the same actions replayed "
         "in the real world. Advantage correlation: 1 = the update in imagination is the one the real outcomes "
         "would give; 0 = noise (docs/rl.md, `gymnast rl-signal`)."), "", *header, *rows(figures), "",
    ]
    weak = summary.get("signal_weak")
    if weak:
        lines += [f"The weak tasks alone ({', '.join(weak['tasks'])}; {weak['rollouts']} rollouts):", "",
                  *header, *rows(weak), ""]
    return [*lines, "Per task: [signal/signal.md](signal/signal.md).", ""]


def _fidelity(model: dict | None) -> list[str]:
    if not model:
        return []
    if "skipped" in model:
        return [f"**The world model**: fidelity not measured ({model['skipped']}).", ""]
    control, per_frame = model.get("controllability") or {}, model.get("actions_per_frame", 1)
    # A model of one frame per chunk of N actions is measured at the first frame it imagines at or after each step.
    first, eighth, last = (measured_step(h, per_frame) for h in (1, 8, 32))
    lines = [(f"**The world model** on {model.get('episodes')} held-out episodes, open loop: PSNR {number(model.get('psnr_h1'))} dB "
              f"{'one step' if first == 1 else f'{first} steps'} ahead, {number(model.get('psnr_h8'))} at {eighth} and "
              f"{number(model.get('psnr_h32'))} at {last} steps (repeating the last real frame: "
              f"{number(model.get('copy_last_psnr_h32'))} at {last}); on the pixels that move, "
              f"{number(model.get('moving_psnr_h32'))} dB at {last} steps (repeating: {number(model.get('copy_last_moving_psnr_h32'))})"
              + (f"; it imagines one frame per {per_frame} actions." if per_frame > 1 else "."))]
    if control.get("matched_psnr") is not None:
        lines.append(f"Controllability: its rollout matches the real rollout of the same actions at {number(control['matched_psnr'])} dB "
                     f"and of other actions at {number(control['mismatched_psnr'])} dB; it picks the right real rollout "
                     f"{pct(control['identification_accuracy'])} of the time.")
    return [" ".join(lines), ""]


def _ranking(roc: dict | None) -> str:
    """The judge's ROC on the real held-out cases in words (nothing for a judge measured before it was read out)."""
    if not roc or roc.get("auc") is None:
        return ""
    return (f" On real video its P(success) ranks a success above a failure {pct(roc['auc'])} of the time (AUC); the "
            f"best threshold for these very cases would pass at least {pct(roc['at_tpr'])} of the successes at FPR "
            f"{number(roc['lowest_fpr'])}.")


def evidence_section(summary: dict) -> list[str]:
    judge, rollouts = summary["judge"], summary.get("judge_rollouts")
    learned = (f" It also learned from {rollouts['episodes']} real rollouts of the SFT policy ({rollouts['successes']} "
               f"successful, {rollouts['real_interactions']:,} real interactions)." if rollouts else "")
    lines = [*_fidelity(summary.get("world_model")),
             ("**The judge** on held-out episodes (its own training stage): "
              f"real video TPR {number(judge.get('real_tpr'))}, FPR {number(judge.get('real_fpr'))}; "
              f"imagined video TPR {number(judge.get('imagined_tpr'))}, FPR {number(judge.get('imagined_fpr'))}."
              f"{_ranking(judge.get('real_roc'))}{learned}"), ""]
    for name, rows in summary["watch"].items():
        if not rows:
            continue
        lines += [(f"**Reward-hacking watch, {arm(name).title}**: imagined rollouts replayed action for action "
                  "in the real world."), "",
                  "| step | imagined success | real success of the same actions | agreement | judged successes that failed for real |",
                  "|---|---|---|---|---|"]
        for row in rows:
            lines.append(f"| {row['step']} | {pct(row.get('imagined_success'))} | {pct(row.get('real_success'))} | "
                         f"{pct(row.get('agreement'))} | {pct(row.get('false_success'))} |")
        lines.append("")
    curve = summary["curves"].get("rl_wm_judge", [])
    if curve:
        lines += ["**Imagined against real success during world-model RL (judge)**, greedy, on the evaluation seeds:", "",
                  "| step | judged in the world model | real world |", "|---|---|---|"]
        lines += [f"| {p['step']} | {pct(p['own'])} | {pct(p['real'])} |" for p in curve]
        lines.append("")
    return lines
