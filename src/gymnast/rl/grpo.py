"""The pure maths of GRPO for a VLA whose action chunk is N discrete tokens decoded in parallel.

Legend: B start states (groups), G rollouts per group, M policy calls (rows) in a batch, N action
tokens per call.

Implemented: critic-free GRPO. Each rollout's advantage is its reward normalised within the group
of G rollouts from one start state; every action token of every policy call in that rollout is
then trained under that one advantage with the PPO-clipped surrogate, with DAPO's separate lower
and upper bounds ("clip-higher"). The two papers this follows:

- World-Gymnast (Sharma et al., 2026): GRPO, group 8, clip 0.2 low / 0.28 high, no KL, no entropy
  bonus, rollout temperature 1.6, dynamic sampling that keeps groups whose success rate lies in
  [0.1, 0.9] (`keep_groups`), one gradient step per iteration, lr 5e-6.
- VLA-RFT (2025): GRPO, 400 steps, 16 start states x group 16, clip 0.2, no KL, entropy 0.003.

Where this departs from them:

- Token-level averaging over all tokens of the batch (DAPO): the loss is a sum over the batch's
  unmasked tokens divided by their count, not a mean per sequence then over sequences. Every token
  weighs the same, and micro-batching is exact when each micro-batch gets the batch's count.
- NaN rewards ("could not score") get advantage exactly 0 and are left out of their group's mean
  and std, so one failed score neither trains the policy nor shifts its siblings' advantages.
- A group with no spread in its finite rewards (or fewer than 2 of them) gets advantage 0: it
  carries no signal, and dividing by a std of ~0 would turn rounding noise into huge advantages.
- Dynamic sampling's success-rate window applies to binary rewards only; with a continuous reward
  a group is kept when its rewards differ at all (`keep_varied_groups`), since a group of failures
  still ranks its rollouts by how close they came.
- The entropy bonus takes the exact entropy of each token's categorical distribution (our action
  tokens are categorical), unlike VLA-RFT, whose flow-matching head gets its log-prob from the
  Gaussian noise of its integration steps.
- An optional k3 KL penalty to a frozen reference policy, off by default as in both papers.
- An optional MOPO-style penalty on the world-model ensemble's disagreement, subtracted from each
  rollout's reward before group normalisation (`penalise_disagreement`), off by default: neither
  paper has one; MOPO (Yu et al., 2020) penalises each imagined step's reward by the ensemble's
  uncertainty, and our reward is one per rollout, so the per-step penalties are averaged.

Per-call credit (`reward_to_go`, `call_advantages`; `--credit reward-to-go`): with a reward that
scores every action (the dense ones), each policy call is credited with the rewards from its own
actions on, normalised against the group's other rollouts at the same call, instead of every call
of a rollout sharing the whole rollout's advantage. A call then carries none of the noise of the
rewards earned before it, which a 150-action episode of ~19 calls otherwise spreads over all of
them (the variance that a learned critic would also remove, without the critic). With
`--credit critic` a learned critic is that baseline (`gae_advantages`, `gymnast.rl.critic`): PPO's
generalised advantage estimation over calls, against the critic's value of what each call saw.

With one gradient step per iteration old_logp equals logp at that step, so the ratio is 1 and the
clip acts only once a batch is reused for several steps. Both log-probs of the ratio (and the
entropy) must come from the same distribution: the policy at the rollout temperature.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor


def _at_least_float32(x: Tensor) -> Tensor:
    # exp(logp - old_logp) in bf16 keeps ~3 significant digits, coarser than the clip bounds.
    return x.to(torch.promote_types(x.dtype, torch.float32))


def _centred_and_std(rewards: Tensor) -> tuple[Tensor, Tensor]:
    """(B, G) rewards minus their group's mean over finite entries (0 where not finite), and (B, 1)
    each group's population std (unbiased=False) over them."""
    finite = rewards.isfinite()
    count = finite.sum(dim=1, keepdim=True).clamp_min(1)  # (B, 1); the clamp only guards 0 / 0
    mean = torch.where(finite, rewards, 0.0).sum(dim=1, keepdim=True) / count
    centred = torch.where(finite, rewards - mean, 0.0)
    return centred, (centred.square().sum(dim=1, keepdim=True) / count).sqrt()


def group_advantages(rewards: Tensor, normalize_std: bool = True, eps: float = 1e-6) -> tuple[Tensor, dict[str, float]]:
    """GRPO's group-normalised advantage, (r - mean) / (std + eps), per group over finite rewards.

    The std is the population std (unbiased=False) of the group's finite rewards. Non-finite
    rewards (NaN: the reward could not score) are excluded from the mean and std and get advantage
    exactly 0; so does every member of a group with fewer than 2 finite rewards or no spread.

    Args:
        rewards: (B, G) rewards, NaN where unscored.
        normalize_std: divide by the group std; False gives r - mean (Dr. GRPO).
        eps: added to the std so small spreads do not explode.

    Returns:
        (advantages (B, G) in at least float32, metrics) with "train/zero_variance_groups" (the
        fraction of groups without signal) and "reward/nan_fraction".

    Raises:
        ValueError: rewards is not (B, G) with G >= 1.
    """
    if rewards.ndim != 2 or rewards.shape[1] < 1:
        raise ValueError(f"rewards must be (B, G) with G >= 1, got {tuple(rewards.shape)}")
    rewards = _at_least_float32(rewards)
    finite = rewards.isfinite()  # (B, G)
    centred, std = _centred_and_std(rewards)
    signal = keep_varied_groups(rewards)[:, None]  # (B, 1); a group without spread has nothing to rank
    if normalize_std:
        centred = centred / (std + eps)
    advantages = torch.where(signal, centred, 0.0)
    groups = max(rewards.shape[0], 1)
    metrics = {"train/zero_variance_groups": (~signal).sum().item() / groups,
               "reward/nan_fraction": (~finite).sum().item() / (groups * rewards.shape[1])}
    return advantages, metrics


def reward_to_go(step_rewards: Tensor, chunk: int, calls: int) -> Tensor:
    """Each policy call's share of its rollout's score: the rewards of the actions from the call on.

    A rollout's score is the mean of its counted step rewards; call s (actions s*K onward) is
    credited with their sum from action s*K on, divided by the same count, so call 0's reward-to-go
    is the score and later calls carry none of the rewards earned before them, which their
    tokens could not have caused. Centred on the group's at each call (`call_advantages`), this is
    GRPO with a per-call baseline: the group's other rollouts at the same call.

    Args:
        step_rewards: (R, T) per-action rewards, NaN where a step does not count (after an end);
            a rollout whose every step is NaN could not be scored and stays NaN.
        chunk: K actions per policy call.
        calls: S policy calls per rollout (S * K >= T pads with steps that do not count).

    Returns:
        (R, S) reward-to-go of each call, in at least float32.
    """
    if step_rewards.ndim != 2 or chunk < 1 or calls * chunk < step_rewards.shape[1]:
        raise ValueError(f"need (R, T) step rewards with T <= calls * chunk, got {tuple(step_rewards.shape)}, "
                         f"{calls} calls of {chunk}")
    rewards = _at_least_float32(step_rewards)
    padded = torch.nn.functional.pad(rewards, (0, calls * chunk - rewards.shape[1]), value=math.nan)
    counted = padded.isfinite()
    per_call = torch.where(counted, padded, 0.0).view(len(padded), calls, chunk).sum(dim=2)  # (R, S)
    after = per_call.flip(1).cumsum(1).flip(1)  # (R, S) sums from each call to the end
    count = counted.sum(dim=1, keepdim=True)  # (R, 1)
    return torch.where(count > 0, after / count.clamp_min(1), math.nan)


def call_advantages(returns: Tensor, acting: Tensor, group_size: int, normalize_std: bool = True,
                    eps: float = 1e-6) -> Tensor:
    """(R, S) advantages of each call's reward-to-go against those of its group's rollouts that
    were still acting at the same call, on the scale of the group's whole rollouts.

    The baseline is per call: the mean reward-to-go at that call of the group's rollouts still
    acting there. A rollout that has already ended (a success) is left out of the later calls'
    baselines: its reward there was earned by calls before, and counting it would charge the
    rollouts still going for having been slower, which their later calls did not cause. The scale
    is per group: the std of the rollouts' whole returns (call 0), as `group_advantages` divides by.
    Dividing each call by its own spread instead would blow up the late calls where the rollouts
    barely differ (measured: it learned more slowly on fixed scenes than whole-rollout credit).

    Args:
        returns: (R, S) `reward_to_go`, R = B * G with each group's G rollouts adjacent.
        acting: (R, S) bool, the calls that executed an action.
        group_size: G.
        normalize_std: divide by the group's std of whole returns (False: Dr. GRPO's r - mean).
        eps: added to the std.

    Returns:
        (R, S) advantages in at least float32; 0 where a call has fewer than two acting rollouts in
        its group, where the group's whole returns do not differ, and where a return is NaN.
    """
    if returns.shape != acting.shape or returns.ndim != 2 or returns.shape[0] % group_size:
        raise ValueError(f"need (R, S) returns and acting with R a multiple of {group_size}, got "
                         f"{tuple(returns.shape)} and {tuple(acting.shape)}")
    calls = returns.shape[1]
    returns = _at_least_float32(returns).view(-1, group_size, calls)  # (B, G, S)
    counted = acting.view(-1, group_size, calls) & returns.isfinite()
    count = counted.sum(dim=1, keepdim=True)  # (B, 1, S)
    mean = torch.where(counted, returns, 0.0).sum(dim=1, keepdim=True) / count.clamp_min(1)
    centred = torch.where(counted & (count > 1), returns - mean, 0.0)  # (B, G, S)
    whole = returns[:, :, 0]  # (B, G) each rollout's return: its score
    signal = keep_varied_groups(whole)[:, None, None]  # (B, 1, 1)
    if normalize_std:
        _, std = _centred_and_std(whole)  # (B, 1)
        centred = centred / (std[:, :, None] + eps)
    return torch.where(signal, centred, 0.0).view(-1, calls)


def gae_advantages(returns: Tensor, values: Tensor, acting: Tensor, lam: float, normalize_std: bool = True,
                   eps: float = 1e-6) -> tuple[Tensor, Tensor]:
    """Generalised advantage estimation over policy calls, against a learned critic's values.

    Call s's reward is its share of the rollout's score, ``returns[s] - returns[s + 1]``
    (`reward_to_go`), and the rollout ends after its last acting call (value 0 beyond it); with no
    discount, as the score is an undiscounted mean, delta_s = r_s + V_{s+1} - V_s and
    A_s = delta_s + lam * A_{s+1}. lam = 1 gives the return minus the value, lam = 0 the one-call
    temporal difference. The critic's targets are A + V (the lambda-returns), as PPO fits them.

    Args:
        returns: (R, S) `reward_to_go`; NaN for a rollout that could not be scored.
        values: (R, S) the critic's values of the calls' observations (ignored where not acting).
        acting: (R, S) bool, the calls that executed an action.
        lam: GAE's lambda in [0, 1].
        normalize_std: centre the advantages of the counted calls on their mean and divide by their
            std, PPO's normalisation over the batch; False leaves them as estimated.
        eps: added to the std.

    Returns:
        (advantages, targets), each (R, S) in at least float32; both 0 where a call did not act or
        its rollout is unscored.
    """
    if not (returns.shape == values.shape == acting.shape) or returns.ndim != 2:
        raise ValueError(f"need (R, S) returns, values and acting alike, got {tuple(returns.shape)}, "
                         f"{tuple(values.shape)} and {tuple(acting.shape)}")
    if not 0 <= lam <= 1:
        raise ValueError(f"GAE's lambda must lie in [0, 1], got {lam}")
    counted = acting & returns.isfinite()
    returns = torch.where(counted, _at_least_float32(returns), 0.0)
    values = torch.where(counted, _at_least_float32(values), 0.0)
    following = torch.nn.functional.pad(returns[:, 1:], (0, 1))  # (R, S) the next call's return, 0 after the end
    deltas = returns - following + torch.nn.functional.pad(values[:, 1:], (0, 1)) - values
    advantages = torch.zeros_like(deltas)
    running = torch.zeros(len(deltas), dtype=deltas.dtype)
    for s in reversed(range(deltas.shape[1])):
        running = torch.where(counted[:, s], deltas[:, s] + lam * running, 0.0)
        advantages[:, s] = running
    targets = torch.where(counted, advantages + values, 0.0)
    if normalize_std and counted.sum() > 1:
        chosen = advantages[counted]
        advantages = torch.where(counted, (advantages - chosen.mean()) / (chosen.std() + eps), 0.0)
    return advantages, targets


def penalise_disagreement(rewards: Tensor, disagreement: Tensor, coef: float) -> Tensor:
    """MOPO's pessimism for one reward per rollout: r - coef * the rollout's mean disagreement.

    The mean over the frames a rollout showed, not the max: MOPO subtracts the uncertainty at every
    step, whose sum over a rollout is its length times the mean; dividing by the length keeps the
    penalty on the reward's scale whatever the rollout's length (a stopped rollout is shorter), and
    the mean is steadier than one worst frame, which a single blurry frame decides.

    Args:
        rewards: (R,) one reward per rollout, NaN where unscored (stays NaN).
        disagreement: (R, T) per imagined frame, NaN after the rollout's end.
        coef: lambda, the penalty's weight.

    Returns:
        (R,) penalised rewards in at least float32; a rollout that showed no frame is not penalised.
    """
    if disagreement.ndim != 2 or disagreement.shape[0] != rewards.shape[0]:
        raise ValueError(f"need rewards (R,) and disagreement (R, T), got {tuple(rewards.shape)}, {tuple(disagreement.shape)}")
    shown = disagreement.isfinite()  # (R, T)
    mean = torch.where(shown, disagreement, 0.0).sum(dim=1) / shown.sum(dim=1).clamp_min(1)  # (R,)
    return _at_least_float32(rewards) - coef * mean


def keep_groups(success: Tensor, low: float, high: float) -> Tensor:
    """Dynamic sampling (DAPO, World-Gymnast): which groups still carry a learning signal.

    Args:
        success: (B, G) float, 1 success / 0 failure / NaN unknown.
        low: smallest success rate kept (inclusive).
        high: largest success rate kept (inclusive).

    Returns:
        (B,) bool: the success rate over the group's finite entries lies in [low, high]. A group
        with no finite entry is dropped.

    Raises:
        ValueError: success is not 2-D, or low > high.
    """
    if success.ndim != 2:
        raise ValueError(f"success must be (B, G), got {tuple(success.shape)}")
    if low > high:
        raise ValueError(f"keep_groups needs low <= high, got [{low}, {high}]")
    finite = success.isfinite()  # (B, G)
    count = finite.sum(dim=1)  # (B,)
    # float64 so that k / G compares with the bounds as Python's k / G would: 1 / 10 >= 0.1 holds.
    rate = torch.where(finite, success.double(), 0.0).sum(dim=1) / count.clamp_min(1)
    return (count > 0) & (rate >= low) & (rate <= high)


def keep_varied_groups(rewards: Tensor) -> Tensor:
    """Dynamic sampling for continuous rewards: which groups' finite rewards differ at all.

    These are also the groups `group_advantages` gives nonzero advantages: the others carry no
    signal.

    Args:
        rewards: (B, G) rewards, NaN where unscored.

    Returns:
        (B,) bool: the group has two finite rewards that differ. A group with fewer than two finite
        rewards is dropped.

    Raises:
        ValueError: rewards is not 2-D.
    """
    if rewards.ndim != 2:
        raise ValueError(f"rewards must be (B, G), got {tuple(rewards.shape)}")
    finite = rewards.isfinite()  # (B, G)
    # Spread is max > min, not std > 0: the float mean of equal rewards can round, leaving
    # |r - mean| ~ 1e-8 and small spurious advantages (of order 1 with eps = 0).
    top = torch.where(finite, rewards, -math.inf).amax(dim=1)  # (B,); -inf without a finite reward
    bottom = torch.where(finite, rewards, math.inf).amin(dim=1)  # (B,); equal to top with one
    return top > bottom


def k3_kl(logp: Tensor, ref_logp: Tensor) -> Tensor:
    """Schulman's k3 estimator of KL(pi || ref) per token, from log-probs of tokens sampled from pi.

    k3 = exp(ref - logp) - (ref - logp) - 1: unbiased, non-negative, and 0 where the two agree.

    Args:
        logp: log-probs under the policy pi, any shape.
        ref_logp: log-probs of the same tokens under the reference, same shape.

    Returns:
        k3 per token, same shape. Raises ValueError if the shapes differ.
    """
    if logp.shape != ref_logp.shape:
        raise ValueError(f"logp {tuple(logp.shape)} and ref_logp {tuple(ref_logp.shape)} must match")
    log_ratio = ref_logp - logp
    # expm1 avoids the cancellation in exp(x) - 1 near 0; the clamp absorbs a last-ulp negative.
    return (torch.expm1(log_ratio) - log_ratio).clamp_min(0.0)


def policy_loss(
    logp: Tensor,
    old_logp: Tensor,
    advantages: Tensor,
    mask: Tensor,
    clip_low: float,
    clip_high: float,
    total_tokens: int | None = None,
    ref_logp: Tensor | None = None,
    kl_coef: float = 0.0,
    entropy: Tensor | None = None,
    entropy_coef: float = 0.0,
) -> tuple[Tensor, dict[str, float]]:
    """The PPO-clipped surrogate with separate bounds, averaged over tokens (DAPO).

    Per token, with ratio = exp(logp - old_logp) and A the row's advantage:
    objective = min(ratio A, clip(ratio, 1 - clip_low, 1 + clip_high) A), and the loss is
    -(objective - kl_coef k3 + entropy_coef entropy) summed over masked tokens / total_tokens.
    Given the full batch's total_tokens, the losses (and gradients) of micro-batches sum to those
    of the batch; every metric is likewise a sum over this call's tokens / total_tokens.

    Args:
        logp: (M, N) log-probs of the sampled tokens under the policy being trained.
        old_logp: (M, N) their log-probs under the policy that sampled them (treated as constant).
        advantages: (M,) one advantage per row (policy call), shared by its N tokens, or (M, N) one
            per token (a row's advantage weighted token by token, `gymnast.rl.reanchor`); treated
            as constant.
        mask: (M, N) bool, True for tokens that count.
        clip_low: the ratio is clipped below at 1 - clip_low.
        clip_high: the ratio is clipped above at 1 + clip_high.
        total_tokens: the divisor; default mask.sum(). Pass the whole batch's when micro-batching.
        ref_logp: (M, N) log-probs under a frozen reference, for the k3 KL penalty and metric.
        kl_coef: weight of the KL penalty.
        entropy: (M, N) entropy of each token's categorical distribution (gradient flows).
        entropy_coef: weight of the entropy bonus.

    Returns:
        (loss scalar, metrics): "train/policy_loss" (the surrogate part), "train/clip_fraction"
        (tokens where the clipped term is the smaller), "train/ratio", and "train/kl" /
        "train/entropy" when ref_logp / entropy are given.

    Raises:
        ValueError: shapes disagree, mask is not bool, total_tokens < 1, or a clip bound is < 0.
    """
    tokens = {"logp": logp, "old_logp": old_logp, "mask": mask, "ref_logp": ref_logp, "entropy": entropy}
    tokens = {name: x for name, x in tokens.items() if x is not None}
    if (logp.ndim != 2 or advantages.shape not in (logp.shape[:1], logp.shape)
            or any(x.shape != logp.shape for x in tokens.values())):
        got = ", ".join(f"{name} {tuple(x.shape)}" for name, x in (tokens | {"advantages": advantages}).items())
        raise ValueError(f"policy_loss expects (M, N) token tensors and (M,) or (M, N) advantages, got {got}")
    if mask.dtype != torch.bool:
        raise ValueError(f"mask must be bool, got {mask.dtype}")
    if clip_low < 0 or clip_high < 0:
        raise ValueError(f"clip bounds must be >= 0, got clip_low={clip_low}, clip_high={clip_high}")
    if total_tokens is None:
        total_tokens = int(mask.sum().item())
    if total_tokens < 1:
        raise ValueError(f"total_tokens must be >= 1, got {total_tokens}")

    # Masked-out entries may hold anything (padding, inf): zero them before exp, because masking only
    # after it would still send 0 * inf = NaN into their gradient through torch.where.
    def clean(x: Tensor) -> Tensor:
        return torch.where(mask, _at_least_float32(x), 0.0)

    logp = clean(logp)
    old_logp = clean(old_logp).detach()
    adv = _at_least_float32(advantages).detach()
    # (M, 1) broadcast over the N tokens, or (M, N) one per token
    adv = adv[:, None] if adv.ndim == 1 else torch.where(mask, adv, 0.0)
    ratio = torch.exp(logp - old_logp)  # (M, N)
    unclipped = ratio * adv
    clipped = ratio.clamp(1.0 - clip_low, 1.0 + clip_high) * adv
    objective = torch.minimum(unclipped, clipped)  # pessimistic: the clip only ever removes gain
    per_token = -objective
    sums = {"train/policy_loss": -objective, "train/clip_fraction": (clipped < unclipped).float(),
            "train/ratio": ratio}
    if ref_logp is not None:
        kl = k3_kl(logp, clean(ref_logp).detach())
        per_token = per_token + kl_coef * kl
        sums["train/kl"] = kl
    if entropy is not None:
        entropy = clean(entropy)
        per_token = per_token - entropy_coef * entropy
        sums["train/entropy"] = entropy
    loss = torch.where(mask, per_token, 0.0).sum() / total_tokens
    # One stack and one transfer for all metrics, rather than a device sync per metric.
    stacked = torch.stack([torch.where(mask, v.detach(), 0.0).sum() for v in sums.values()]) / total_tokens
    return loss, dict(zip(sums, stacked.tolist(), strict=True))
