"""GRPO maths: against plain-Python loop references, edge cases, gradients, micro-batching."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from gymnast.rl import grpo
from gymnast.rl.grpo import group_advantages, k3_kl, keep_groups, keep_varied_groups, policy_loss

# ---------------------------------------------------------------- slow plain-Python references


def loop_group_advantages(rewards, normalize_std, eps):
    advantages, silent = [], 0
    for row in rewards:
        finite = [r for r in row if math.isfinite(r)]
        if len(finite) < 2 or max(finite) == min(finite):
            advantages.append([0.0] * len(row))
            silent += 1
            continue
        mean = sum(finite) / len(finite)
        std = math.sqrt(sum((r - mean) ** 2 for r in finite) / len(finite))
        scale = std + eps if normalize_std else 1.0
        advantages.append([(r - mean) / scale if math.isfinite(r) else 0.0 for r in row])
    nans = sum(not math.isfinite(r) for row in rewards for r in row)
    return advantages, silent / len(rewards), nans / (len(rewards) * len(rewards[0]))


def loop_keep_groups(success, low, high):
    keep = []
    for row in success:
        finite = [s for s in row if math.isfinite(s)]
        keep.append(bool(finite) and low <= sum(finite) / len(finite) <= high)
    return keep


def loop_keep_varied_groups(rewards):
    return [len({r for r in row if math.isfinite(r)}) > 1 for row in rewards]


def loop_policy_loss(logp, old_logp, advantages, mask, clip_low, clip_high, total, ref_logp, kl_coef,
                     entropy, entropy_coef):
    loss = surrogate = clipped_count = ratio_sum = kl_sum = entropy_sum = 0.0
    for i, row in enumerate(mask):
        a = advantages[i]
        for j, counted in enumerate(row):
            if not counted:
                continue
            ratio = math.exp(logp[i][j] - old_logp[i][j])
            unclipped = ratio * a
            clipped = min(max(ratio, 1 - clip_low), 1 + clip_high) * a
            objective = min(unclipped, clipped)
            d = ref_logp[i][j] - logp[i][j]
            kl = math.exp(d) - d - 1
            loss += -(objective - kl_coef * kl + entropy_coef * entropy[i][j])
            surrogate += -objective
            clipped_count += clipped < unclipped
            ratio_sum += ratio
            kl_sum += kl
            entropy_sum += entropy[i][j]
    metrics = {"train/policy_loss": surrogate, "train/clip_fraction": clipped_count, "train/ratio": ratio_sum,
               "train/kl": kl_sum, "train/entropy": entropy_sum}
    return loss / total, {k: v / total for k, v in metrics.items()}


# ---------------------------------------------------------------- a tiny categorical policy

N_TOKENS, VOCAB, OBS = 3, 5, 4


class TinyPolicy(nn.Module):
    """obs (M, OBS) -> logits (M, N_TOKENS, VOCAB): one linear head, separate weights per token."""

    def __init__(self, seed: int = 0):
        super().__init__()
        self.head = nn.Linear(OBS, N_TOKENS * VOCAB)
        generator = torch.Generator().manual_seed(seed)  # not the global RNG: tests stay independent
        with torch.no_grad():
            for parameter in self.head.parameters():
                parameter.copy_(torch.randn(parameter.shape, generator=generator))

    def forward(self, obs):
        return self.head(obs).view(obs.shape[0], N_TOKENS, VOCAB)


def sample_tokens(policy, obs, generator):
    with torch.no_grad():
        probs = policy(obs).softmax(-1).view(-1, VOCAB)
    return torch.multinomial(probs, 1, generator=generator).view(obs.shape[0], N_TOKENS)


def token_logp_and_entropy(policy, obs, tokens):
    log_probs = policy(obs).log_softmax(-1)  # (M, N, V)
    logp = log_probs.gather(-1, tokens[..., None])[..., 0]
    entropy = -(log_probs.exp() * log_probs).sum(-1)
    return logp, entropy


# ---------------------------------------------------------------- group_advantages


def random_rewards(generator, b=40, g=6):
    rewards = torch.rand(b, g, generator=generator, dtype=torch.float64)
    rewards[: b // 4] = (rewards[: b // 4] > 0.5).double()  # binary success rewards, often all equal
    rewards[b // 4 : b // 3] = 0.7  # constant groups
    rewards[torch.rand(b, g, generator=generator) < 0.25] = math.nan
    rewards[-1] = math.nan  # an all-NaN group
    rewards[-2, 1:] = math.nan  # a single finite reward
    return rewards


@pytest.mark.parametrize("normalize_std", [True, False])
def test_group_advantages_match_loop_reference(normalize_std):
    rewards = random_rewards(torch.Generator().manual_seed(0))
    advantages, metrics = group_advantages(rewards, normalize_std=normalize_std, eps=1e-6)
    expected, silent, nans = loop_group_advantages(rewards.tolist(), normalize_std, 1e-6)
    torch.testing.assert_close(advantages, torch.tensor(expected, dtype=torch.float64))
    assert metrics["train/zero_variance_groups"] == pytest.approx(silent)
    assert metrics["reward/nan_fraction"] == pytest.approx(nans)
    assert 0 < silent < 1 and 0 < nans < 1


def test_groups_without_signal_get_exactly_zero_advantage():
    rewards = torch.tensor([[0.1, 0.1, 0.1, 0.1], [1.0, 1.0, math.nan, 1.0], [math.nan, 3.0, math.nan, math.nan],
                            [math.nan] * 4, [0.0, 1.0, 0.0, 0.0]])
    advantages, metrics = group_advantages(rewards)
    assert torch.equal(advantages[:4], torch.zeros(4, 4))
    assert advantages[4].abs().sum() > 0
    assert metrics["train/zero_variance_groups"] == pytest.approx(4 / 5)
    assert torch.isfinite(advantages).all()


def test_nan_rewards_get_zero_advantage_and_leave_the_others_unchanged():
    with_nans = torch.tensor([[1.0, math.nan, 3.0, 0.0, math.nan]])
    without = torch.tensor([[1.0, 3.0, 0.0]])
    for normalize_std in (True, False):
        a_nan, _ = group_advantages(with_nans, normalize_std=normalize_std)
        a_clean, _ = group_advantages(without, normalize_std=normalize_std)
        assert a_nan[0, 1] == 0 and a_nan[0, 4] == 0
        torch.testing.assert_close(a_nan[0, [0, 2, 3]], a_clean[0])


def test_group_advantages_use_population_std():
    advantages, _ = group_advantages(torch.tensor([[0.0, 2.0]]), eps=0.0)
    assert advantages.tolist() == [[-1.0, 1.0]]  # mean 1, population std 1 (the unbiased std is sqrt(2))


def test_group_advantages_reject_wrong_shape():
    with pytest.raises(ValueError, match=r"\(8,\)"):
        group_advantages(torch.zeros(8))


# ---------------------------------------------------------------- keep_groups


def test_keep_groups_matches_loop_reference():
    generator = torch.Generator().manual_seed(1)
    success = (torch.rand(60, 8, generator=generator) < torch.rand(60, 1, generator=generator)).float()
    success[torch.rand(60, 8, generator=generator) < 0.2] = math.nan
    success[0] = math.nan
    kept = keep_groups(success, 0.1, 0.9)
    assert kept.tolist() == loop_keep_groups(success.tolist(), 0.1, 0.9)
    assert 0 < kept.sum() < 60


def test_keep_groups_bounds_are_inclusive_and_unknown_groups_are_dropped():
    rows = [[1.0] * k + [0.0] * (10 - k) for k in (0, 1, 5, 9, 10)]  # success rates 0, .1, .5, .9, 1
    rows += [[math.nan] * 10, [1.0, math.nan] + [0.0] * 8]  # unknown; 1 success in 9 known entries
    success = torch.tensor(rows)
    assert keep_groups(success, 0.1, 0.9).tolist() == [False, True, True, True, False, False, True]
    assert keep_groups(success, 0.0, 1.0).tolist() == [True] * 5 + [False, True]
    with pytest.raises(ValueError, match="low <= high"):
        keep_groups(success, 0.9, 0.1)


# ---------------------------------------------------------------- keep_varied_groups


def test_keep_varied_groups_matches_loop_reference_and_the_groups_with_advantages():
    rewards = random_rewards(torch.Generator().manual_seed(3))
    kept = keep_varied_groups(rewards)
    assert kept.tolist() == loop_keep_varied_groups(rewards.tolist())
    assert 0 < kept.sum() < len(rewards)
    advantages, _ = group_advantages(rewards)
    assert (advantages.abs().sum(dim=1) > 0).tolist() == kept.tolist()


def test_keep_varied_groups_keeps_any_spread_and_drops_groups_with_fewer_than_two_rewards():
    rewards = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 1e-6], [0.3, math.nan, 0.3], [math.nan, 0.5, math.nan],
                            [math.nan] * 3, [-1.0, 2.0, math.nan]])
    assert keep_varied_groups(rewards).tolist() == [False, True, False, False, False, True]
    with pytest.raises(ValueError, match=r"\(8,\)"):
        keep_varied_groups(torch.zeros(8))


# ---------------------------------------------------------------- k3_kl


def test_k3_is_non_negative_zero_when_equal_and_matches_loop():
    generator = torch.Generator().manual_seed(2)
    logp = -5 * torch.rand(200, generator=generator, dtype=torch.float64)
    ref = -5 * torch.rand(200, generator=generator, dtype=torch.float64)
    kl = k3_kl(logp, ref)
    assert (kl >= 0).all()
    expected = [math.exp(r - p) - (r - p) - 1 for p, r in zip(logp.tolist(), ref.tolist(), strict=True)]
    torch.testing.assert_close(kl, torch.tensor(expected, dtype=torch.float64))
    assert torch.equal(k3_kl(logp, logp), torch.zeros(200, dtype=torch.float64))
    near = logp + 1e-9 * torch.randn(200, generator=generator, dtype=torch.float64)
    assert (k3_kl(logp, near) >= 0).all()


def test_k3_expectation_under_the_policy_is_the_exact_kl():
    generator = torch.Generator().manual_seed(3)
    log_pi = torch.randn(7, generator=generator, dtype=torch.float64).log_softmax(0)
    log_ref = torch.randn(7, generator=generator, dtype=torch.float64).log_softmax(0)
    exact = (log_pi.exp() * (log_pi - log_ref)).sum()
    torch.testing.assert_close((log_pi.exp() * k3_kl(log_pi, log_ref)).sum(), exact)


# ---------------------------------------------------------------- policy_loss


@pytest.mark.parametrize("explicit_total", [False, True])
def test_policy_loss_matches_loop_reference(explicit_total):
    generator = torch.Generator().manual_seed(4)
    m, n = 12, 5
    f64 = {"generator": generator, "dtype": torch.float64}
    old_logp = -3 * torch.rand(m, n, **f64)
    logp = old_logp + 0.5 * torch.randn(m, n, **f64)  # ratios on both sides of both bounds
    ref_logp = old_logp + 0.3 * torch.randn(m, n, **f64)
    advantages = torch.randn(m, **f64)
    entropy = torch.rand(m, n, **f64)
    mask = torch.rand(m, n, generator=generator) < 0.7
    total = 97 if explicit_total else int(mask.sum())
    loss, metrics = policy_loss(logp, old_logp, advantages, mask, 0.2, 0.28, total_tokens=total if explicit_total
                                else None, ref_logp=ref_logp, kl_coef=0.05, entropy=entropy, entropy_coef=0.003)
    expected, expected_metrics = loop_policy_loss(logp.tolist(), old_logp.tolist(), advantages.tolist(),
                                                  mask.tolist(), 0.2, 0.28, total, ref_logp.tolist(), 0.05,
                                                  entropy.tolist(), 0.003)
    assert loss.item() == pytest.approx(expected, rel=1e-12)
    assert metrics == pytest.approx(expected_metrics, rel=1e-12)
    assert 0 < metrics["train/clip_fraction"] < 1


def test_per_token_advantages_are_the_rows_spread_or_weighted_token_by_token():
    generator = torch.Generator().manual_seed(5)
    m, n = 6, 4
    old_logp = -2 * torch.rand(m, n, generator=generator)
    logp = (old_logp + 0.3 * torch.randn(m, n, generator=generator)).requires_grad_()
    advantages = torch.randn(m, generator=generator)
    mask = torch.rand(m, n, generator=generator) < 0.8
    by_row, _ = policy_loss(logp, old_logp, advantages, mask, 0.2, 0.28)
    spread, _ = policy_loss(logp, old_logp, advantages[:, None].expand(m, n), mask, 0.2, 0.28)
    assert spread.item() == pytest.approx(by_row.item(), rel=1e-6)
    # a token weighted 0 teaches nothing; the others learn as before
    weights = torch.ones(m, n)
    weights[0, 0] = 0.0
    weighted, _ = policy_loss(logp, old_logp, advantages[:, None] * weights, mask, 0.2, 0.28)
    (gradient,) = torch.autograd.grad(weighted, logp)
    (reference,) = torch.autograd.grad(by_row, logp)
    assert gradient[0, 0] == 0 and torch.allclose(gradient[1:], reference[1:])


def test_policy_loss_reports_kl_and_entropy_only_when_given():
    logp = torch.zeros(2, 3)
    _, metrics = policy_loss(logp, logp, torch.ones(2), torch.ones(2, 3, dtype=torch.bool), 0.2, 0.28)
    assert set(metrics) == {"train/policy_loss", "train/clip_fraction", "train/ratio"}
    assert metrics["train/ratio"] == pytest.approx(1.0)
    assert metrics["train/clip_fraction"] == 0.0


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_advantage_sign_moves_sampled_token_logp_after_one_sgd_step(sign):
    policy = TinyPolicy()
    obs = torch.randn(1, OBS, generator=torch.Generator().manual_seed(5))
    tokens = sample_tokens(policy, obs, torch.Generator().manual_seed(6))
    before, _ = token_logp_and_entropy(policy, obs, tokens)
    # The very same tensor as old_logp, as a trainer taking one step per batch may pass it: old_logp
    # must be treated as a constant, or the ratio would be exp(0) with no gradient at all.
    loss, _ = policy_loss(before, before, torch.tensor([sign]), torch.ones_like(tokens, dtype=torch.bool), 0.2, 0.28)
    optimizer = torch.optim.SGD(policy.parameters(), lr=0.1)
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    with torch.no_grad():
        after, _ = token_logp_and_entropy(policy, obs, tokens)
    change = (after - before.detach())[0]  # each token has its own rows of the head, so each moves
    assert ((sign * change) > 0).all(), change


def test_clipped_tokens_contribute_no_gradient_and_others_do():
    # Row 0 has A > 0, row 1 has A < 0; ratios per token: above, inside, below the bounds [0.8, 1.28].
    ratios = torch.tensor([[1.5, 1.1, 0.7], [0.7, 1.1, 1.5]], dtype=torch.float64)
    old_logp = torch.full((2, 3), -1.0, dtype=torch.float64)
    logp = (old_logp + ratios.log()).requires_grad_()
    loss, metrics = policy_loss(logp, old_logp, torch.tensor([1.0, -1.0], dtype=torch.float64),
                                torch.ones(2, 3, dtype=torch.bool), clip_low=0.2, clip_high=0.28)
    loss.backward()
    clipped = torch.tensor([[True, False, False], [True, False, False]])
    assert (logp.grad[clipped] == 0).all()
    # Inside the bounds, and the pessimistic side outside them (ratio 0.7 with A > 0, 1.5 with A < 0).
    assert (logp.grad[~clipped] != 0).all()
    assert metrics["train/clip_fraction"] == pytest.approx(2 / 6)


def test_micro_batches_with_the_batch_token_count_reproduce_the_full_batch():
    policy = TinyPolicy().double()
    frozen = TinyPolicy(seed=1).double()
    generator = torch.Generator().manual_seed(7)
    m = 10
    obs = torch.randn(m, OBS, generator=generator, dtype=torch.float64)
    tokens = sample_tokens(policy, obs, generator)
    with torch.no_grad():
        old_logp, _ = token_logp_and_entropy(policy, obs, tokens)
        old_logp += 0.3 * torch.randn(m, N_TOKENS, generator=generator, dtype=torch.float64)  # a stale policy
        ref_logp, _ = token_logp_and_entropy(frozen, obs, tokens)
    advantages = torch.randn(m, generator=generator, dtype=torch.float64)
    mask = torch.rand(m, N_TOKENS, generator=generator) < 0.7
    total = int(mask.sum())
    settings = {"clip_low": 0.2, "clip_high": 0.28, "total_tokens": total, "kl_coef": 0.1, "entropy_coef": 0.01}

    def loss_and_grads(rows):
        logp, entropy = token_logp_and_entropy(policy, obs[rows], tokens[rows])
        loss, metrics = policy_loss(logp, old_logp[rows], advantages[rows], mask[rows], ref_logp=ref_logp[rows],
                                    entropy=entropy, **settings)
        loss.backward()
        return loss.item(), metrics

    policy.zero_grad()
    full_loss, full_metrics = loss_and_grads(slice(0, m))
    full_grads = [p.grad.clone() for p in policy.parameters()]
    policy.zero_grad()
    parts = [loss_and_grads(rows) for rows in (slice(0, 2), slice(2, 7), slice(7, m))]  # uneven, accumulated
    for full, accumulated in zip(full_grads, (p.grad for p in policy.parameters()), strict=True):
        assert torch.allclose(full, accumulated)
    assert sum(loss for loss, _ in parts) == pytest.approx(full_loss)
    for key, value in full_metrics.items():
        assert sum(metrics[key] for _, metrics in parts) == pytest.approx(value), key
    assert full_metrics["train/clip_fraction"] > 0


def test_masked_tokens_with_garbage_log_probs_change_nothing():
    logp = torch.tensor([[-1.0, math.nan], [-2.0, math.inf]], requires_grad=True)
    old_logp = torch.tensor([[-1.2, math.inf], [-1.5, math.nan]])
    mask = torch.tensor([[True, False], [True, False]])
    loss, metrics = policy_loss(logp, old_logp, torch.tensor([1.0, -1.0]), mask, 0.2, 0.28, ref_logp=old_logp,
                                kl_coef=0.1)
    loss.backward()
    assert torch.isfinite(loss) and all(math.isfinite(v) for v in metrics.values())
    assert torch.isfinite(logp.grad).all() and (logp.grad[:, 1] == 0).all()
    clean, _ = policy_loss(logp[:, :1], old_logp[:, :1], torch.tensor([1.0, -1.0]), mask[:, :1], 0.2, 0.28,
                           ref_logp=old_logp[:, :1], kl_coef=0.1)
    assert loss.item() == pytest.approx(clean.item())


@pytest.mark.parametrize(
    ("changes", "pattern"),
    [
        ({"old_logp": torch.zeros(4, 2)}, r"old_logp \(4, 2\)"),
        ({"advantages": torch.zeros(4, 2)}, r"advantages \(4, 2\)"),
        ({"mask": torch.ones(3, 4, dtype=torch.bool)}, r"mask \(3, 4\)"),
        ({"ref_logp": torch.zeros(4)}, r"ref_logp \(4,\)"),
        ({"entropy": torch.zeros(1, 3)}, r"entropy \(1, 3\)"),
        ({"mask": torch.ones(4, 3)}, "bool"),
        ({"total_tokens": 0}, "total_tokens"),
        ({"clip_low": -0.1}, "clip"),
        ({"clip_high": -0.1}, "clip"),
    ],
)
def test_policy_loss_rejects_bad_inputs_naming_the_shapes(changes, pattern):
    inputs = {"logp": torch.zeros(4, 3), "old_logp": torch.zeros(4, 3), "advantages": torch.zeros(4),
              "mask": torch.ones(4, 3, dtype=torch.bool), "clip_low": 0.2, "clip_high": 0.28} | changes
    with pytest.raises(ValueError, match=pattern):
        policy_loss(**inputs)


def test_policy_loss_rejects_an_empty_mask_without_a_token_count():
    logp = torch.zeros(2, 3)
    with pytest.raises(ValueError, match="total_tokens"):
        policy_loss(logp, logp, torch.zeros(2), torch.zeros(2, 3, dtype=torch.bool), 0.2, 0.28)


def test_k3_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match=r"\(2, 3\).*\(3, 2\)"):
        k3_kl(torch.zeros(2, 3), torch.zeros(3, 2))


def test_reward_to_go_credits_each_call_with_the_rewards_from_its_actions_on():
    # two calls of 2 actions; the second rollout ended after 3 actions without success (NaN after)
    steps = torch.tensor([[0.1, 0.2, 0.3, 0.4], [0.5, 0.0, 0.6, float("nan")]])
    returns = grpo.reward_to_go(steps, chunk=2, calls=2)
    assert torch.allclose(returns, torch.tensor([[1.0 / 4, 0.7 / 4], [1.1 / 3, 0.6 / 3]]))
    assert torch.allclose(returns[:, 0], torch.nanmean(steps, dim=1))  # call 0's is the rollout's score


def test_reward_to_go_pads_calls_past_the_horizon_and_keeps_unscored_rollouts_nan():
    steps = torch.tensor([[1.0, 1.0, 1.0], [float("nan")] * 3])
    returns = grpo.reward_to_go(steps, chunk=2, calls=3)
    assert torch.allclose(returns[0], torch.tensor([1.0, 1 / 3, 0.0]))
    assert returns[1].isnan().all()
    with pytest.raises(ValueError, match="calls"):
        grpo.reward_to_go(steps, chunk=1, calls=2)


def test_call_advantages_compare_each_call_with_the_rollouts_still_acting_there():
    # one group of 3, two calls; rollout 0 ended after its first call (a success)
    returns = torch.tensor([[0.9, 0.5], [0.2, 0.1], [0.4, 0.3]])
    acting = torch.tensor([[True, False], [True, True], [True, True]])
    advantages = grpo.call_advantages(returns, acting, group_size=3, normalize_std=False)
    assert torch.allclose(advantages[:, 0], returns[:, 0] - returns[:, 0].mean())
    # at call 1 the finished rollout's 0.5 is not the others' baseline
    assert torch.allclose(advantages[:, 1], torch.tensor([0.0, -0.1, 0.1]))


def test_call_advantages_of_constant_calls_equal_the_rollout_advantages():
    rewards = torch.tensor([[0.0, 1.0, 2.0, 5.0], [3.0, 3.0, 1.0, 0.0]])  # (B=2, G=4)
    returns = rewards.reshape(-1, 1).expand(-1, 3)  # every call of a rollout with its rollout's return
    per_call = grpo.call_advantages(returns, torch.ones(8, 3, dtype=torch.bool), group_size=4)
    per_rollout, _ = grpo.group_advantages(rewards)
    assert torch.allclose(per_call, per_rollout.reshape(-1, 1).expand(-1, 3))
    with pytest.raises(ValueError, match="multiple of 3"):
        grpo.call_advantages(returns, torch.ones(8, 3, dtype=torch.bool), group_size=3)


def test_call_advantages_keep_the_groups_scale_at_calls_where_rollouts_barely_differ():
    returns = torch.tensor([[1.0, 0.001], [0.0, 0.0]])  # whole returns differ by 1, the last call by 0.001
    advantages = grpo.call_advantages(returns, torch.ones(2, 2, dtype=torch.bool), group_size=2)
    assert torch.allclose(advantages[:, 0], torch.tensor([1.0, -1.0]), atol=1e-5)
    assert torch.allclose(advantages[:, 1], torch.tensor([0.001, -0.001]), atol=1e-5)
