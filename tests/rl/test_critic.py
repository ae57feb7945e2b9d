"""`--credit critic`: GAE over policy calls, the critic built from the policy, its fit, and a run
that resumes with the critic where it was."""

import json
import shutil

import pytest
import torch

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.envs.sim_vector import SimVectorEnv
from gymnast.policy.load import load_policy
from gymnast.rl.critic import CallCritic, ValueCritic
from gymnast.rl.grpo import gae_advantages
from gymnast.rl.rollout import collect_rollouts, dataset_starts
from gymnast.utils.checkpoint import LAST, load_extra
from gymnast.utils.metrics import read_metrics

from rl_helpers import POLICY
from test_rl_loop import _comparable, _rl_args

# Two rollouts of three calls; the second ended after its second call. Returns are reward-to-go.
RETURNS = torch.tensor([[0.6, 0.4, 0.1], [0.5, 0.2, 0.0]])
ACTING = torch.tensor([[True, True, True], [True, True, False]])
VALUES = torch.tensor([[0.3, 0.3, 0.3], [0.3, 0.1, 9.0]])  # 9.0: a value where nothing acted, ignored


def test_gae_with_lambda_one_is_the_return_minus_the_value():
    advantages, targets = gae_advantages(RETURNS, VALUES, ACTING, 1.0, normalize_std=False)
    expected = torch.where(ACTING, RETURNS - VALUES, 0.0)
    assert torch.allclose(advantages, expected) and torch.allclose(targets, torch.where(ACTING, RETURNS, 0.0))


def test_gae_with_lambda_zero_is_one_calls_temporal_difference():
    advantages, _ = gae_advantages(RETURNS, VALUES, ACTING, 0.0, normalize_std=False)
    # reward of call s is G_s - G_{s+1}; the value after the last acting call is 0
    expected = torch.tensor([[0.2 + 0.3 - 0.3, 0.3 + 0.3 - 0.3, 0.1 + 0.0 - 0.3],
                             [0.3 + 0.1 - 0.3, 0.2 + 0.0 - 0.1, 0.0]])
    assert torch.allclose(advantages, expected)


def test_gae_leaves_unscored_rollouts_out_and_normalises_the_rest():
    returns = RETURNS.clone()
    returns[1] = float("nan")
    advantages, targets = gae_advantages(returns, VALUES, ACTING, 0.95, normalize_std=True)
    assert (advantages[1] == 0).all() and (targets[1] == 0).all()
    assert advantages[0].mean().abs() < 1e-6 and advantages[0].std() == pytest.approx(1.0, abs=1e-4)
    with pytest.raises(ValueError, match="lambda"):
        gae_advantages(RETURNS, VALUES, ACTING, 1.5)
    with pytest.raises(ValueError, match="returns, values and acting"):
        gae_advantages(RETURNS, VALUES[:, :2], ACTING, 0.9)


def test_the_critic_starts_from_the_policys_encoder_and_its_fit_lowers_its_error(rl_dataset):
    policy = load_policy(POLICY)
    critic = ValueCritic.for_policy(policy)
    assert torch.equal(critic.vision_position, policy.vision_position)
    assert torch.equal(critic.text_film.weight, policy.text_film.weight)
    starts = dataset_starts(rl_dataset)[:2]
    with SimVectorEnv(2, policy.chunk_size, EnvConfig(image_size=96, horizon=3 * policy.chunk_size)) as env:
        batch = collect_rollouts(env, policy, starts, 1.0, torch.Generator().manual_seed(0))
    returns = torch.tensor([[0.9, 0.6, 0.3], [0.1, 0.05, 0.0]])[:, :batch.tokens.shape[1]]
    fitter = CallCritic(critic, lr=1e-3, epochs=5, gae_lambda=1.0, micro_batch=4)
    losses = [fitter.advantages_and_fit(batch, returns, True, torch.Generator().manual_seed(1))[1]["critic/loss"]
              for _ in range(4)]
    assert losses[-1] < losses[0]
    advantages, metrics = fitter.advantages_and_fit(batch, returns, False)
    assert advantages.shape == returns.shape and metrics["critic/explained_variance"] > 0


def test_a_run_with_the_critic_resumes_with_the_critic_where_it_was(rl_dataset, tmp_path, capsys):
    whole, resumed = tmp_path / "whole", tmp_path / "resumed"
    main(_rl_args("real", "sim-dense", whole, rl_dataset, "--credit", "critic"))
    assert json.loads((whole / "config.json").read_text())["rl"]["credit"] == "critic"
    trained = [m for m in read_metrics(whole) if "critic/loss" in m]
    assert [m["step"] for m in trained] == [1, 2]
    # The same run, as if it had been stopped after its first step: its last checkpoint is step 1's.
    shutil.copytree(whole, resumed)
    shutil.rmtree(resumed / "checkpoints" / "000002")
    (resumed / "checkpoints" / LAST).write_text("000001")
    critic_after_one = load_extra(resumed / "checkpoints" / "000001", "critic")["critic"]
    assert any(not torch.equal(critic_after_one[k], v) for k, v in
               load_extra(whole / "checkpoints" / "000002", "critic")["critic"].items())
    main(["rl", "--out", str(resumed), "--resume"])
    again, expected = _comparable(read_metrics(resumed)), _comparable(read_metrics(whole))
    assert [m.keys() for m in again] == [m.keys() for m in expected]
    for line, expected_line in zip(again, expected):
        assert line == pytest.approx(expected_line, rel=1e-5, abs=1e-7)
    with pytest.raises(SystemExit):
        main(_rl_args("real", "sim", tmp_path / "binary", rl_dataset, "--credit", "critic"))
    assert "--credit critic" in capsys.readouterr().err
