"""The GRPO signal of imagination: the advantage correlation against hand-computed cases, the dense
reference, and one real measurement with the committed models through the command line."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from gymnast.cli import main
from gymnast.experiment.practice_signal import SignalConfig, dense_return, read_out, start_episodes
from gymnast.experiment.signal_report import signal_figures
from gymnast.reward.select import make_reward
from gymnast.reward.spec import RewardSpec

RESULTS = Path(__file__).resolve().parents[2] / "results"
JUDGE = RESULTS / "judge" / "one_camera" / "judge"
READOUTS = ("score", "probability", "score, real video (reference)", "probability, real video (reference)",
            "real dense reward (reference)")


def test_a_readout_that_ranks_every_group_as_reality_does_correlates_fully():
    real = torch.tensor([[1, 0, 0, 1], [0, 0, 1, 0]], dtype=torch.bool)
    figures = signal_figures(real.float() * 0.7 + 0.1, real, binary=False)
    assert figures["advantage_correlation"] == pytest.approx(1.0)
    assert figures["correlation_ci_low"] == pytest.approx(1.0) and figures["correlation_ci_high"] == pytest.approx(1.0)
    assert figures["reinforced_real_success"] == 1.0 and figures["discouraged_real_success"] == 0.0
    assert figures["signal_groups"] == figures["real_signal_groups"] == 1.0


def test_a_readout_that_ranks_backwards_correlates_negatively_and_reinforces_failures():
    real = torch.tensor([[1, 0, 0, 1], [0, 0, 1, 0]], dtype=torch.bool)
    figures = signal_figures((~real).float(), real, binary=True)
    assert figures["advantage_correlation"] == pytest.approx(-1.0)
    assert figures["reinforced_real_success"] == 0.0 and figures["discouraged_real_success"] == 1.0
    assert figures["agreement"] == 0.0 and figures["false_success"] == 1.0 and figures["imagined_success"] == 0.625


def test_the_correlation_is_the_cosine_of_the_group_advantages():
    values = torch.tensor([[0.9, 0.1, 0.5], [0.2, 0.2, 0.8]])
    real = torch.tensor([[1, 1, 0], [0, 1, 1]], dtype=torch.bool)

    def advantages(row):  # GRPO's group normalisation, written out: population std, eps 1e-6
        mean = sum(row) / len(row)
        std = math.sqrt(sum((x - mean) ** 2 for x in row) / len(row))
        return [(x - mean) / (std + 1e-6) for x in row]

    read = [a for row in values.tolist() for a in advantages(row)]
    truth = [a for row in real.float().tolist() for a in advantages(row)]
    cosine = sum(r * t for r, t in zip(read, truth)) / math.sqrt(sum(r * r for r in read) * sum(t * t for t in truth))
    assert signal_figures(values, real, binary=False)["advantage_correlation"] == pytest.approx(cosine, abs=1e-5)


def test_a_readout_without_spread_gives_no_signal_and_no_correlation():
    real = torch.tensor([[1, 0], [0, 1]], dtype=torch.bool)
    figures = signal_figures(torch.ones(2, 2), real, binary=True)
    assert figures["advantage_correlation"] is None and figures["signal_groups"] == 0.0
    assert figures["reinforced_real_success"] is None and figures["false_success"] == 0.5


def test_the_dense_reference_counts_the_maximum_from_the_success_on():
    rewards = torch.tensor([[1.0, 2.0, 3.0, 4.0], [1.0, 1.0, float("nan"), float("nan")]])
    success = torch.tensor([[False, False, True, True], [False, False, False, False]])
    assert dense_return(rewards, success).tolist() == pytest.approx([(1 + 2 + 10 + 10) / 40, 0.1])


@pytest.mark.parametrize("hold_steps", [1, 3])
def test_a_per_frame_judge_is_read_at_every_horizon_from_one_pass(hold_steps):
    judge = make_reward(RewardSpec.judge(JUDGE))
    judge.config = dataclasses.replace(judge.config, hold_steps=hold_steps)  # a run cut by a horizon holds
    frames = torch.randint(0, 256, (2, 11, 96, 96, 3), dtype=torch.uint8)
    readouts = read_out(judge, frames, ["reach the goal"] * 2, (5, 10))
    for h in (5, 10):
        probability = judge.probability(frames[:, : h + 1], ["reach the goal"] * 2)
        assert torch.allclose(readouts["probability"][h], probability, atol=1e-5)
        assert torch.equal(readouts["score"][h], judge.score(frames[:, : h + 1], ["reach the goal"] * 2))


def test_a_progress_judge_is_read_as_its_score_at_every_horizon():
    from gymnast.reward.judges.base import JudgeConfig
    from gymnast.reward.judges.progress import ProgressJudge

    judge = ProgressJudge(JudgeConfig(width=16, image_size=16)).eval()
    frames = torch.randint(0, 256, (2, 11, 16, 16, 3), dtype=torch.uint8)
    readouts = read_out(judge, frames, ["push the puck"] * 2, (5, 10))
    assert set(readouts) == {"score"}
    for h in (5, 10):
        # The cut video is judged in a batch of fewer frames: where bfloat16 is native its convolutions
        # round differently with the batch (random frames score mid-range, where that shows).
        assert torch.allclose(readouts["score"][h], judge.score(frames[:, : h + 1], ["push the puck"] * 2), atol=1e-3)


def test_a_state_models_reward_head_is_read_as_its_score_and_its_verdict_at_every_horizon():
    from gymnast.reward.base import RewardContext
    from gymnast.reward.state_reward import StateReward
    from gymnast.world_model.state_model import StateModel, StateModelConfig

    reward = StateReward(StateModel(StateModelConfig(state_dim=6, hidden=8, layers=1)).eval())
    frames = torch.zeros(3, 11, 8, 8, 3, dtype=torch.uint8)
    context = RewardContext(start_state=torch.randn(3, 6), actions=torch.rand(3, 10, 4) * 2 - 1)
    instructions = ["push the puck"] * 3
    readouts = read_out(reward, frames, instructions, (5, 10), context)
    assert set(readouts) == {"score", "verdict"}
    for h in (5, 10):
        cut = RewardContext(start_state=context.start_state, actions=context.actions[:, :h])
        assert torch.equal(readouts["score"][h], reward.score(frames[:, : h + 1], instructions, cut))
        assert torch.equal(readouts["verdict"][h], reward.verdict(instructions, cut))
    with pytest.raises(ValueError, match="start states and the actions"):
        read_out(reward, frames, instructions, (5,))


def test_the_return_correlation_holds_the_readout_against_the_real_dense_return():
    real = torch.tensor([[1, 0, 0, 0], [0, 0, 0, 0]], dtype=torch.bool)
    returns = torch.tensor([[0.9, 0.5, 0.2, 0.1], [0.3, 0.6, 0.1, 0.2]])
    figures = signal_figures(returns * 2 + 1, real, binary=False, real_return=returns)
    assert figures["return_correlation"] == pytest.approx(1.0)
    assert figures["return_ci_low"] == pytest.approx(1.0)
    backwards = signal_figures(-returns, real, binary=False, real_return=returns)
    assert backwards["return_correlation"] == pytest.approx(-1.0)
    assert signal_figures(returns, real, binary=False)["return_correlation"] is None


def test_a_reward_that_reads_more_than_the_video_is_refused_before_anything_loads(tmp_path):
    from gymnast.experiment.practice_signal import measure_signal_runs

    for name in ("verified", "sim", "sim-dense"):
        with pytest.raises(ValueError, match="rl-signal reads a judge"):
            measure_signal_runs(tmp_path / "no-policy", tmp_path / "no-wm", RewardSpec.parse(name), SignalConfig())


def test_settings_that_cannot_rank_are_refused():
    with pytest.raises(ValueError, match="group_size"):
        SignalConfig(group_size=1)
    with pytest.raises(ValueError, match="multiple of group_size"):
        SignalConfig(group_size=8, batch=12)
    with pytest.raises(ValueError, match="temperature"):
        SignalConfig(temperature=0.0)


@pytest.mark.slow
def test_the_command_measures_the_committed_models_against_real_replays(tmp_path):
    out = tmp_path / "signal"
    main(["rl-signal", "--policy", str(RESULTS / "sft" / "policy"), "--wm", str(RESULTS / "world_model" / "wm"),
          "--reward", f"judge:{JUDGE}", "--out", str(out), "--tasks", "reach-v3", "--starts-per-task", "2",
          "--group-size", "4", "--horizons", "10", "20", "--batch", "8", "--workers", "1"])
    report = json.loads((out / "signal.json").read_text())
    threshold = make_reward(RewardSpec.judge(JUDGE)).config.threshold
    assert len(report["rollouts"]) == 8 and [r["group"] for r in report["rollouts"]] == [0] * 4 + [1] * 4
    assert report["interactions"] == 8 * 20  # every replay runs to the longest horizon
    for record in report["rollouts"]:
        assert set(record["readouts"]) == set(READOUTS)
        assert record["real"]["10"] <= record["real"]["20"]  # success by a horizon stays a success
        for h in ("10", "20"):  # the verdict is the probability against the judge's threshold
            assert record["readouts"]["score"][h] == float(record["readouts"]["probability"][h] >= threshold)
    rows = {(row["readout"], row["horizon"]) for row in report["readouts"]}
    assert rows == {(name, h) for name in READOUTS for h in (10, 20)}
    assert "advantage correlation" in (out / "signal.md").read_text()


def test_the_brief_of_some_tasks_pools_only_their_groups():
    from gymnast.experiment.signal_report import REAL_DENSE, SCORE, signal_brief, signal_table

    def rollout(task: str, score: float, success: bool, dense: float) -> dict:
        return {"task": task, "real": {"4": success}, "real_return": {"4": dense},
                "readouts": {SCORE: {"4": score}, REAL_DENSE: {"4": dense}}}

    # reach's imagined scores rank its groups as reality does; push's rank them backwards.
    records = [rollout("reach-v3", 0.9, True, 0.8), rollout("reach-v3", 0.1, False, 0.2),
               rollout("push-v3", 0.1, True, 0.7), rollout("push-v3", 0.9, False, 0.3)]
    binary = {SCORE: False, REAL_DENSE: False}
    report = {"settings": {"horizons": [4], "group_size": 2, "binary_readouts": []}, "rollouts": records,
              "readouts": signal_table(records, [4], 2, binary), "interactions": 16}
    everything = signal_brief(report)
    assert everything["rollouts"] == 4 and everything["real_interactions"] == 16
    assert everything["imagined"]["advantage_correlation"] == pytest.approx(0.0)
    reach = signal_brief(report, ["reach-v3", "pick-place-v3"])
    assert reach["tasks"] == ["reach-v3"] and reach["rollouts"] == 2
    assert reach["imagined"]["advantage_correlation"] == pytest.approx(1.0)
    assert signal_brief(report, ["push-v3"])["imagined"]["advantage_correlation"] == pytest.approx(-1.0)
    assert signal_brief(report, ["peg-insert-side-v3"]) is None


def test_the_signal_of_an_rl_run_is_measured_on_the_practice_it_does(tmp_path, capsys):
    import dataclasses

    from gymnast.envs.kinds import IMAGINED, REAL
    from gymnast.experiment.practice_signal import practice_of
    from gymnast.rl.config import RLConfig, RLRun
    from gymnast.utils.checkpoint import write_run_config

    def rl_run(name: str, env, reward: str, data: str | None, **settings) -> Path:
        run = RLRun("runs/sft", env, RewardSpec.parse(reward), wm="runs/wm" if env.imagined else None, data=data)
        write_run_config(tmp_path / name, {"rl": dataclasses.asdict(RLConfig(**settings)), "run": run.to_json()})
        return tmp_path / name

    practice = rl_run("imagined", IMAGINED, "state:runs/state", "data/rollouts", tasks="reach-v3", group_size=6,
                      temperature=1.2, horizon=20, keyframes="failures", seed=3)
    inputs, settings = practice_of(practice)
    assert inputs == {"policy": "runs/sft", "wm": "runs/wm", "reward": "state:runs/state"}
    config = SignalConfig(**settings)  # settings a SignalConfig takes
    assert (config.tasks, config.group_size, config.temperature, config.horizons, config.seed) == ("reach-v3", 6, 1.2, (20,), 3)
    assert (config.data, config.keyframes, config.batch) == ("data/rollouts", "failures", 60)
    with pytest.raises(ValueError, match="not in imagination"):
        practice_of(rl_run("real", REAL, "sim-dense", None))
    with pytest.raises(SystemExit):
        main(["rl-signal", "--out", str(tmp_path / "signal"), "--wm", "runs/wm"])
    assert "rl-signal needs --policy, --reward (or --like RUN" in capsys.readouterr().err


def test_starts_take_every_held_out_episode_once_before_lending_trained_ones_and_repeat_last():
    draw = np.random.default_rng(0)
    few = start_episodes([1, 2, 3], [10, 11], 2, draw)
    assert len(few) == 2 and len(set(few)) == 2 and set(few) <= {1, 2, 3}
    lent = start_episodes([1, 2], [10, 11, 12], 4, draw)
    assert {1, 2} <= set(lent) and len(set(lent)) == 4 and len(set(lent) & {10, 11, 12}) == 2
    short = start_episodes([1], [10], 5, draw)
    assert len(short) == 5 and set(short) == {1, 10}
    assert start_episodes([], [7, 8], 2, draw) in ([7, 8], [8, 7])


def test_tasks_named_in_task_starts_get_their_own_number_of_scenes_never_one_twice():
    from gymnast.config import EnvConfig
    from gymnast.experiment.practice_signal import fresh_starts

    config = SignalConfig(tasks="reach-v3,push-v3", starts_per_task=1, task_starts={"push-v3": 3})
    assert [config.starts_for(task) for task in ("reach-v3", "push-v3")] == [1, 3]
    starts = fresh_starts({task: config.starts_for(task) for task in ("reach-v3", "push-v3")}, EnvConfig(), seed=0)
    assert [start.task for start in starts] == ["reach-v3", "push-v3", "push-v3", "push-v3"]
    assert len({start.seed for start in starts}) == 4
    # The same counts for every task draw the scenes they drew before counts could differ.
    even = fresh_starts({"reach-v3": 2, "push-v3": 2}, EnvConfig(), seed=0)
    draw = np.random.default_rng(0)
    from gymnast.envs.tasks import DATA_SEEDS
    seeds = draw.choice(DATA_SEEDS.stop - DATA_SEEDS.start, size=4, replace=False) + DATA_SEEDS.start
    assert [start.seed for start in even] == [int(seed) for seed in seeds]
    with pytest.raises(ValueError, match=r"task_starts\['push-v3'\] must be at least 1"):
        SignalConfig(task_starts={"push-v3": 0})
    with pytest.raises(ValueError, match=r"names \['door-open-v3'\], not among its tasks"):
        SignalConfig(tasks="reach-v3", task_starts={"door-open-v3": 4})
