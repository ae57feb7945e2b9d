"""Imagination under a policy, with the committed models: judged imagined verdicts against real
replays of the same actions, the replay itself, the report files and the command."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import REAL
from gymnast.envs.starts import evaluation_starts
from gymnast.experiment.imagination import ImaginationConfig, measure_imagination
from gymnast.policy.load import load_policy
from gymnast.reward.base import RewardNeeds
from gymnast.reward.select import make_reward
from gymnast.reward.spec import RewardSpec
from gymnast.rl.evaluate import replay_actions
from gymnast.rl.rollout import collect_rollouts
from gymnast.world_model.base import load_world_model

pytestmark = pytest.mark.slow

RESULTS = Path(__file__).resolve().parents[2] / "results"
POLICY = RESULTS / "sft" / "policy"
WORLD_MODEL = RESULTS / "world_model" / "wm"
JUDGE = RESULTS / "judge" / "one_camera" / "judge"
CONFIG = ImaginationConfig(tasks="reach-v3", episodes=2, horizon=20, batch=2, videos=2)


class SpyReward:
    """The judge, recording the shape of every video it scores and its scores."""

    binary = True
    needs = RewardNeeds()

    def __init__(self, judge) -> None:
        self.judge, self.calls = judge, []

    def score(self, frames, instructions, context):
        scores = self.judge.score(frames, instructions, context)
        self.calls.append((tuple(frames.shape), scores.tolist()))
        return scores


class SaysSuccess:
    """A binary reward that calls every video a success: every replay failure is a false success."""

    binary = True
    needs = RewardNeeds()

    def score(self, frames, instructions, context):
        return torch.ones(frames.shape[0])


class Dense:
    binary = False
    needs = RewardNeeds()

    def score(self, frames, instructions, context):
        return torch.full((frames.shape[0],), 0.5)


@pytest.fixture(scope="module")
def models():
    return load_policy(POLICY), load_world_model(WORLD_MODEL)


@pytest.fixture(scope="module")
def measured(models, tmp_path_factory):
    policy, world_model = models
    spy = SpyReward(make_reward(RewardSpec.judge(JUDGE)))
    out = tmp_path_factory.mktemp("imagination")
    return measure_imagination(policy, world_model, spy, CONFIG, out, progress=False), spy, out


def test_counts_agree_with_the_verdicts_and_the_videos_have_the_horizon(measured):
    report, spy, _ = measured
    rows, overall = report["rollouts"], report["overall"]
    assert len(rows) == overall["episodes"] == overall["judged"] == 2
    said, truth = [r["imagined_verdict"] for r in rows], [r["replay_success"] for r in rows]
    pairs = list(zip(said, truth))
    counts = overall["confusion"]
    assert counts == {"tp": pairs.count((True, True)), "fp": pairs.count((True, False)),
                      "fn": pairs.count((False, True)), "tn": pairs.count((False, False))}
    assert sum(counts.values()) == 2 and overall["agreement"] == (counts["tp"] + counts["tn"]) / 2
    assert overall["imagined_success"]["successes"] == sum(said)
    assert overall["replay_success"]["successes"] == sum(truth)
    assert overall["real_success"]["successes"] == sum(r["real_success"] for r in rows)
    assert report["per_task"]["reach-v3"] == overall  # one task: its block is the whole
    # The judge saw each imagined video (start frame + 20 imagined frames), then each real one.
    assert [shape for shape, _ in spy.calls[:2]] == [(1, 21, 96, 96, 3)] * 2
    assert [shape[1] for shape, _ in spy.calls[2:]] == [r["real_length"] + 1 for r in rows]
    assert [r["imagined_score"] for r in rows] == [scores[0] for _, scores in spy.calls[:2]]
    assert [r["real_verdict"] for r in rows] == [scores[0] > 0.5 for _, scores in spy.calls[2:]]
    judge = overall["judge_on_real"]
    assert sum(judge["confusion"].values()) == 2
    assert judge["confusion"]["tp"] + judge["confusion"]["fn"] == sum(r["real_success"] for r in rows)
    # Every imagined action was replayed in the real world; the closed loop stopped at success.
    assert report["interactions"] == {"replay": 2 * 20, "real": sum(r["real_length"] for r in rows),
                                      "total": 2 * 20 + sum(r["real_length"] for r in rows)}


def test_psnr_is_reported_per_step_and_by_horizon_within_the_horizon_only(measured):
    figures = measured[0]["psnr"]
    assert len(figures["curve"]) == len(figures["moving_curve"]) == 20
    assert figures["psnr_h1"] == pytest.approx(figures["curve"][0]) and figures["psnr_h8"] == pytest.approx(figures["curve"][7])
    assert figures["psnr_h32"] is None and figures["moving_psnr_h64"] is None  # beyond a 20-action horizon
    assert 5 < figures["psnr_full"] < 100 and figures["psnr_full"] == pytest.approx(sum(figures["curve"]) / 20)
    # A static background is easy to imagine: the moving pixels score lower than the whole frame.
    assert figures["moving_psnr_full"] < figures["psnr_full"]


def test_the_report_files_hold_the_figures_and_the_videos(measured):
    report, _, out = measured
    assert json.loads((out / "imagination.json").read_text()) == json.loads(json.dumps(report))
    markdown = (out / "imagination.md").read_text()
    counts = report["overall"]["confusion"]
    assert f"| reach-v3 | 2 | {counts['tp']} | {counts['fp']} | {counts['fn']} | {counts['tn']} |" in markdown
    assert "![PSNR per step](psnr.png)" in markdown
    assert (out / "psnr.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(report["videos"]) == 2
    for video in report["videos"]:
        assert (out / video["path"]).stat().st_size > 0 and f"]({video['path']})" in markdown


def test_a_judge_that_calls_everything_a_success_is_caught_by_the_replays(models, measured, tmp_path):
    policy, world_model = models
    report = measure_imagination(policy, world_model, SaysSuccess(), CONFIG, tmp_path, progress=False)
    # Greedy policy, same scenes, same world-model seed: the same actions, so the same replays.
    before = measured[0]["rollouts"]
    assert [r["replay_success"] for r in report["rollouts"]] == [r["replay_success"] for r in before]
    assert [r["real_success"] for r in report["rollouts"]] == [r["real_success"] for r in before]
    overall = report["overall"]
    failures = sum(not r["replay_success"] for r in report["rollouts"])
    assert overall["imagined_success"]["success"] == 1.0
    assert overall["confusion"]["fp"] == failures and overall["confusion"]["fn"] == overall["confusion"]["tn"] == 0
    assert overall["false_success"] == failures / 2
    assert overall["judge_on_real"]["fpr"] in (1.0, None) and overall["judge_on_real"]["tpr"] in (1.0, None)
    # False successes are shown first.
    kinds = [video["kind"] for video in report["videos"]]
    assert kinds.count("false_success") == min(2, failures)
    assert kinds == sorted(kinds, key=lambda kind: kind != "false_success")


def test_replaying_a_real_rollout_reproduces_its_outcome_and_frames(models):
    policy, _ = models
    config = EnvConfig(image_size=96, horizon=30)
    starts = evaluation_starts(["reach-v3"], 2, config)
    envs = EnvFactory(REAL, policy.chunk_size, config, "none", workers=1)
    replays = EnvFactory(REAL, policy.chunk_size, EnvConfig(image_size=96, horizon=30, terminate_on_success=False),
                         "none", workers=1)
    try:
        rollouts = collect_rollouts(envs.get(REAL, 2), policy, starts, 0.0, torch.Generator())
        replay = replay_actions(replays.get(REAL, 2), rollouts.starts, rollouts.actions, rollouts.lengths)
    finally:
        envs.close()
        replays.close()
    success, frames, interactions = replay.success, replay.frames, replay.interactions
    assert success.tolist() == rollouts.success.tolist()
    assert frames.shape == rollouts.frames.shape and frames.dtype == torch.uint8
    for i, length in enumerate(rollouts.lengths.tolist()):
        assert torch.equal(frames[i, : length + 1], rollouts.frames[i, : length + 1])
        assert torch.equal(frames[i, length:], frames[i, length:length + 1].expand_as(frames[i, length:]))
    # Per step: success from the chunk that reached it on, the simulator's rewards up to the end.
    assert replay.success_by_step.any(dim=1).tolist() == success.tolist()
    for i, length in enumerate(rollouts.lengths.tolist()):
        assert torch.allclose(replay.rewards[i, :length], rollouts.env_rewards[i, :length].float())
        assert torch.isnan(replay.rewards[i, length:]).all() and not replay.success_by_step[i, length:].any()
    # Whole chunks are executed, in every episode, until the longest replay's last one.
    chunk = policy.chunk_size
    assert interactions == 2 * min(-(-int(rollouts.lengths.max()) // chunk) * chunk, 30)


def test_a_continuous_reward_is_refused(models):
    policy, world_model = models
    with pytest.raises(ValueError, match="needs a binary reward.*Dense gives continuous scores"):
        measure_imagination(policy, world_model, Dense(), CONFIG)


def test_the_command_measures_and_prints_the_table(tmp_path, capsys):
    out = tmp_path / "imagination"
    main(["imagination", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--tasks", "reach-v3", "--episodes", "1", "--horizon", "10", "--videos", "1", "--out", str(out)])
    printed = capsys.readouterr().out
    report = json.loads((out / "imagination.json").read_text())
    assert report["settings"]["policy"] == str(POLICY) and report["overall"]["episodes"] == 1
    assert "overall" in printed and "tp/fp/fn/tn" in printed and str(out / "imagination.md") in printed
    assert len(list((out / "videos").glob("*.mp4"))) == 1


def test_the_command_refuses_a_continuous_reward_with_a_clear_message(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["imagination", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--reward", "sim-dense",
              "--tasks", "reach-v3", "--episodes", "1", "--out", str(tmp_path)])
    assert "imagination needs a binary reward" in capsys.readouterr().err
