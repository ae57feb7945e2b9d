"""What the reward sees (the rollouts' own video, or their actions replayed in another world) and
how its verdicts are held to the real outcome, against the real simulator and the committed models."""

import dataclasses
import json
import math

import pytest
import torch
from rl_helpers import JUDGE, POLICY, WORLD_MODEL

from gymnast.config import EnvConfig
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import IMAGINED, REAL
from gymnast.policy.load import load_policy
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RLConfig, RLRun
from gymnast.rl.reanchor import frames_at_calls, learning_batch, replay_observations, with_logp_on_observations
from gymnast.rl.rollout import collect_rollouts, dataset_starts
from gymnast.rl.sight import RewardSight, reward_truth_metrics
from gymnast.world_model.base import load_world_model

CONFIG = EnvConfig(image_size=96, horizon=30)


@pytest.fixture(scope="module")
def imagined_and_real(rl_dataset):
    """Two groups of 2 rollouts of the committed policy, imagined and real, from the same starts."""
    policy = load_policy(POLICY)
    starts = [start for start in dataset_starts(rl_dataset) for _ in range(2)]
    envs = EnvFactory(IMAGINED, policy.chunk_size, CONFIG, "mild", workers=1, world_model=load_world_model(WORLD_MODEL))
    try:
        imagined = collect_rollouts(envs.get(IMAGINED, len(starts)), policy, starts, 1.0, torch.Generator().manual_seed(0))
        real = collect_rollouts(envs.get(REAL, len(starts)), policy, starts, 1.0, torch.Generator().manual_seed(0))
        yield envs, imagined, real
    finally:
        envs.close()


def test_imagined_actions_replayed_for_real_carry_the_simulators_outcome_and_its_frames(imagined_and_real):
    envs, imagined, _ = imagined_and_real
    assert imagined.success is None
    seen, spent = RewardSight(envs, IMAGINED, sees=REAL).seen(imagined)
    assert seen.success is not None and seen.env_rewards is not None
    assert spent > 0  # real actions taken to replay them
    assert seen.frames.shape[:2] == (len(imagined.starts), imagined.actions.shape[1] + 1)
    assert torch.equal(seen.actions, imagined.actions) and torch.equal(seen.tokens, imagined.tokens)
    assert not torch.equal(seen.frames[:, 1:], imagined.frames[:, 1:])  # the real world's frames, not the imagined ones


def test_real_actions_re_imagined_have_frames_and_no_outcome(imagined_and_real):
    envs, _, real = imagined_and_real
    seen, _ = RewardSight(envs, REAL, sees=IMAGINED).seen(real)
    assert seen.success is None and seen.env_rewards is None
    assert seen.frames.dtype == torch.uint8 and seen.frames.shape[1] == real.actions.shape[1] + 1
    # from the same real start frame (as the world model reproduces it)
    assert (seen.frames[:, 0].float() - real.frames[:, 0].float()).abs().mean() < 8


def test_the_truth_is_free_where_rollouts_are_real_and_replayed_for_a_few_groups_in_imagination(imagined_and_real):
    envs, imagined, real = imagined_and_real
    truth, spent = RewardSight(envs, REAL).truth(real, real, size=2)
    assert spent == 0 and torch.equal(truth, real.success.float())
    truth, spent = RewardSight(envs, IMAGINED, truth_groups=1).truth(imagined, imagined, size=2)
    assert spent > 0 and int(torch.isfinite(truth).sum()) == 2  # one group of two measured
    truth, spent = RewardSight(envs, IMAGINED).truth(imagined, imagined, size=2)
    assert spent == 0 and not torch.isfinite(truth).any()


def test_a_sight_that_replays_the_rollouts_in_their_own_world_is_refused(imagined_and_real):
    envs = imagined_and_real[0]
    with pytest.raises(ValueError, match="leave --reward-sees out"):
        RewardSight(envs, REAL, sees=REAL)


def test_agreement_false_and_missed_successes_are_counted_as_by_hand():
    verdict = torch.tensor([1.0, 1.0, 0.0, 0.0, 1.0, float("nan")])
    truth = torch.tensor([1.0, 0.0, 0.0, 1.0, float("nan"), 1.0])
    scores = torch.tensor([0.9, 0.8, 0.1, 0.2, 0.7, 0.5])
    values = reward_truth_metrics(verdict, truth, scores, size=2)
    # measured and judged: rollouts 0-3 -> agreement 2/4; said success 0, 1 -> one false of two;
    # real successes 0, 3 -> one missed of two
    assert values["reward/truth_rollouts"] == 5
    assert values["reward/agreement"] == 0.5
    assert values["reward/false_success"] == 0.5 and values["reward/missed_success"] == 0.5
    assert values["reward/truth_success"] == pytest.approx(3 / 5)


def test_the_truth_signal_is_the_correlation_of_group_advantages_with_real_outcomes():
    scores = torch.tensor([0.9, 0.1, 0.2, 0.8, 0.3, 0.7])  # groups of 2
    truth = torch.tensor([1.0, 0.0, 0.0, 1.0, 1.0, 0.0])  # agrees, agrees, disagrees
    advantages = torch.tensor([1.0, -1.0, -1.0, 1.0, -1.0, 1.0]) / math.sqrt(2)
    centred = torch.tensor([0.5, -0.5, -0.5, 0.5, 0.5, -0.5])
    expected = torch.corrcoef(torch.stack([advantages, centred]))[0, 1].item()
    values = reward_truth_metrics(scores.round(), truth, scores, size=2)
    assert values["reward/truth_signal"] == pytest.approx(expected) and expected == pytest.approx(1 / 3)


def test_what_the_reward_sees_is_saved_with_the_run_and_old_runs_saw_their_own():
    run = RLRun(policy="p", env=REAL, reward=RewardSpec.judge(JUDGE), wm="w", reward_sees=IMAGINED)
    assert RLRun.from_json(run.to_json()) == run
    saved = run.to_json()
    del saved["reward_sees"]
    assert RLRun.from_json(saved).reward_sees is None


def test_imagined_rollouts_are_re_imagined_only_in_another_world_model(imagined_and_real):
    envs, imagined, _ = imagined_and_real
    with pytest.raises(ValueError, match="leave --reward-sees out"):
        RewardSight(envs, IMAGINED, sees=IMAGINED)
    chunk = imagined.actions.shape[1] // imagined.observations.shape[1]  # K actions per policy call
    other = EnvFactory(IMAGINED, chunk, CONFIG, "mild", workers=1,
                       world_model=load_world_model(WORLD_MODEL))  # a second copy stands in for another model
    try:
        seen, _ = RewardSight(envs, IMAGINED, sees=IMAGINED, replays=other).seen(imagined)
        assert seen.success is None and seen.frames.shape == imagined.frames.shape
        # the same model re-imagining the same actions from the same start gives the same video back
        assert (seen.frames.float() - imagined.frames.float()).abs().mean() < 1
    finally:
        other.close()


def test_a_reward_world_model_is_refused_without_imagined_replays(rl_dataset, tmp_path, capsys):
    from gymnast.cli import main

    with pytest.raises(SystemExit):
        main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
              "--reward-wm", str(WORLD_MODEL), "--out", str(tmp_path / "run"), "--data", str(rl_dataset),
              "--preset", "debug"])
    assert "--reward-sees imagined" in capsys.readouterr().err


def test_the_frame_before_each_call_is_what_the_policy_saw_there(imagined_and_real):
    _, _, real = imagined_and_real
    calls = real.tokens.shape[1]
    chunk = real.actions.shape[1] // calls
    acting = real.token_mask.any(-1)  # (R, S) calls made before the rollout's end
    assert torch.equal(frames_at_calls(real.frames, calls, chunk)[acting], real.observations[acting])


def test_a_replay_that_renders_only_what_the_policy_reads_keeps_its_outcome_and_those_frames(imagined_and_real):
    envs, imagined, _ = imagined_and_real
    full, spent = RewardSight(envs, IMAGINED, sees=REAL).seen(imagined)
    light, spent_light = RewardSight(envs, IMAGINED, sees=REAL, video=False).seen(imagined)
    calls = imagined.tokens.shape[1]
    chunk = imagined.actions.shape[1] // calls
    assert torch.equal(light.success, full.success) and spent_light == spent
    assert torch.equal(frames_at_calls(light.frames, calls, chunk), frames_at_calls(full.frames, calls, chunk))
    assert not torch.equal(light.frames, full.frames)  # the frames inside a chunk were not rendered


def test_learning_on_replays_holds_the_imagined_actions_to_the_real_frames_at_each_call(imagined_and_real):
    envs, imagined, _ = imagined_and_real
    policy = load_policy(POLICY)
    seen, _ = RewardSight(envs, IMAGINED, sees=REAL, video=False).seen(imagined)
    chunk = policy.chunk_size
    replayed = replay_observations(imagined, seen, chunk)
    assert torch.equal(replayed, frames_at_calls(seen.frames, imagined.tokens.shape[1], chunk))
    assert not torch.equal(replayed[:, 1:], imagined.observations[:, 1:])
    with pytest.raises(ValueError, match="are not those of"):
        replay_observations(imagined, seen.select(torch.arange(1)), chunk)
    advantages = torch.arange(len(imagined.starts), dtype=torch.float32)
    anchored, same = learning_batch(policy, imagined, replayed, advantages, "replays", 1.0, 3)
    assert torch.equal(anchored.observations, replayed) and torch.equal(same, advantages)
    assert torch.equal(anchored.tokens, imagined.tokens) and torch.equal(anchored.rendered, imagined.rendered)
    # both: every call a row twice, once on the frame it acted on and once on its replay's
    doubled, twice = learning_batch(policy, imagined, replayed, advantages, "both", 1.0, 3)
    count = len(imagined.starts)
    assert torch.equal(doubled.observations[:count], imagined.observations)
    assert torch.equal(doubled.observations[count:], replayed)
    assert torch.equal(doubled.logp[:count], imagined.logp) and torch.equal(doubled.logp[count:], anchored.logp)
    assert torch.equal(twice, torch.cat([advantages, advantages]))
    # weighted by importance: each token's advantage on the real frame times how much likelier the
    # policy makes it there than on the imagined frame it was sampled on, capped
    weighted_batch, weighted = learning_batch(policy, imagined, replayed, advantages, "replays", 1.0, 3, 1.0)
    ratio = torch.exp(weighted_batch.logp - imagined.logp).clamp(max=1.0)
    expected = torch.where(imagined.token_mask, advantages[:, None, None] * ratio, 0.0)
    assert weighted.shape == imagined.logp.shape and torch.allclose(weighted, expected)
    assert (weighted.abs() <= advantages.abs()[:, None, None] + 1e-6).all()
    _, both_weighted = learning_batch(policy, imagined, replayed, advantages, "both", 1.0, 3, 1.0)
    assert torch.equal(both_weighted[:count], advantages[:, None, None].expand_as(imagined.logp))
    assert torch.allclose(both_weighted[count:], expected)


def test_the_ratio_starts_from_the_tokens_log_probabilities_on_the_frames_the_update_reads(imagined_and_real):
    envs, imagined, _ = imagined_and_real
    policy = load_policy(POLICY)
    mask = imagined.token_mask
    again = with_logp_on_observations(policy, imagined, 1.0, micro_batch=3)
    # on the frames it sampled on, the policy's log-probabilities are those it sampled with
    assert torch.allclose(again.logp[mask], imagined.logp[mask], atol=1e-4)
    seen, _ = RewardSight(envs, IMAGINED, sees=REAL, video=False).seen(imagined)
    replayed = replay_observations(imagined, seen, policy.chunk_size)
    anchored = with_logp_on_observations(policy, dataclasses.replace(imagined, observations=replayed), 1.0, 3)
    assert not torch.allclose(anchored.logp[mask], imagined.logp[mask], atol=1e-3)
    assert (anchored.logp[~mask] == 0).all()


def test_learning_on_replays_needs_replays_and_trains_from_a_ratio_of_one(rl_dataset, tmp_path, capsys):
    from gymnast.cli import main

    common = ["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", "sim",
              "--data", str(rl_dataset), "--preset", "debug", "--learn-on", "replays"]
    with pytest.raises(SystemExit):
        main(common + ["--out", str(tmp_path / "refused")])
    assert "--reward-sees real" in capsys.readouterr().err
    out = tmp_path / "anchored"
    main(common + ["--reward-sees", "real", "--out", str(out), "--tracker", "none"])
    steps = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    ratios = [row["train/ratio"] for row in steps if "train/ratio" in row]
    assert ratios and all(r == pytest.approx(1.0, abs=1e-5) for r in ratios)
    out = tmp_path / "both"
    main(common[:-1] + ["both", "--reward-sees", "real", "--importance-cap", "1.0", "--out", str(out),
                        "--tracker", "none"])
    steps = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    calls = [row["train/policy_calls"] for row in steps if "train/policy_calls" in row]
    assert calls and all(count == 2 * 8 for count in calls)  # 2 groups x 2 rollouts x 2 calls, twice


def test_learning_on_an_unknown_world_or_weighing_what_is_not_re_anchored_is_refused():
    with pytest.raises(ValueError, match="learn_on must be one of own, replays, both"):
        RLConfig(learn_on="imagined")
    with pytest.raises(ValueError, match="give --learn-on replays or both"):
        RLConfig(importance_cap=1.0)
    with pytest.raises(ValueError, match="importance_cap must be at least 0"):
        RLConfig(learn_on="replays", importance_cap=-1.0)


def test_an_anchored_sight_rolls_out_for_real_and_is_evaluated_in_the_real_world(rl_dataset, tmp_path, capsys):
    from gymnast.cli import main

    common = ["rl", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--reward", "sim", "--data", str(rl_dataset),
              "--preset", "debug", "--tracker", "none"]
    with pytest.raises(SystemExit):
        main(common + ["--env", "anchored", "--out", str(tmp_path / "refused")])
    assert "give both or neither" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(common + ["--env", "imagined", "--anchor-every", "10", "--out", str(tmp_path / "refused_too")])
    assert "give both or neither" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(common + ["--env", "anchored", "--anchor-every", "10", "--disagreement-penalty", "0.5",
                       "--out", str(tmp_path / "refused_lever")])
    assert "--env anchored's rollouts are real" in capsys.readouterr().err
    out = tmp_path / "anchored"
    main(common + ["--env", "anchored", "--anchor-every", "10", "--out", str(out)])
    lines = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    steps = [line for line in lines if "train/lr" in line]
    assert steps and all(line["rollout/real_interactions"] > 0 for line in steps)  # the rollouts are real
    # Seen through the world model, so evaluated both ways: as it practises and in the real world.
    evaluations = [line for line in lines if "eval/real_success" in line]
    assert evaluations and all("eval/own_success" in line for line in evaluations)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env"] == "anchored" and summary["real_interactions"] == steps[-1]["rollout/real_interactions"]
