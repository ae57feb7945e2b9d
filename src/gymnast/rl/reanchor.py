"""Re-anchoring the update on the replays' frames: the policy acts on one world's frames and learns
on another's (`RLConfig.learn_on` replays, or both).

Legend: R rollouts, S policy calls per rollout, N action tokens per call, K actions per chunk,
T actions per rollout, H/W image size.

On the learning ladder (docs/rl.md, "Where learning dies") the policy that acts on imagined frames
and is rewarded by the real outcome of its actions (R3) learns to succeed on imagined frames, and
little of it reaches rendered ones: on door-open its imagined actions succeed for real 72-88% of the
time while the same policy acting on rendered frames succeeds 46%. When those actions are replayed
in the real world for the reward anyway, the real frames they led to are at hand: the update can
hold each action to the real frame at its call instead of the imagined one, so that the policy
learns how to act on what reality shows it. The actions were sampled on the imagined frames, so the
update's ratio starts from the log-probabilities of the same tokens on the real frames under the
policy before the update (`with_logp_on_observations`), not from those it sampled with.

Measured there (docs/rl.md, "Re-anchoring R3 on the real frames"): learning on the real frames
took door-open to 70% in 5 steps, as reality did (R3: 42%), and then stalled, because the policy's
proposals on the imagined frames, which still choose what it learns from, got worse as it improved
on the real ones. Holding each action to both frames (``both``) slowed that decline without ending it.
"""

from __future__ import annotations

import dataclasses
import math

import torch

from gymnast.rl.rollout import Rollouts, call_inputs, concat_rollouts


def frames_at_calls(frames: torch.Tensor, calls: int, chunk: int) -> torch.Tensor:
    """(R, S, H, W, 3) the frame before each policy call: the start frame, then each chunk's last.

    Args:
        frames: (R, T + 1, H, W, 3) the start frame, then one frame per action (the end frame
            repeating after a rollout's end, as `Rollouts.frames` and replays keep them).
        calls: S, the policy calls of the rollouts.
        chunk: K, the actions each call executes.
    """
    index = (torch.arange(calls) * chunk).clamp(max=frames.shape[1] - 1)  # calls after the end see the end
    return frames[:, index]


def replay_observations(rollouts: Rollouts, replays: Rollouts, chunk: int) -> torch.Tensor:
    """(R, S, H, W, 3) the frames the rollouts' replays showed before each policy call: what the
    policy would have seen there had it acted where its actions were replayed. `chunk` is K, the
    actions each policy call executes.

    Raises:
        ValueError: the replays are not of these rollouts (another count or action length), or their
            frames are not the shape of the policy's observations.
    """
    if len(replays.starts) != len(rollouts.starts) or replays.actions.shape != rollouts.actions.shape:
        raise ValueError(f"replays of {len(replays.starts)} rollouts with actions {tuple(replays.actions.shape)} "
                         f"are not those of {len(rollouts.starts)} rollouts with {tuple(rollouts.actions.shape)}")
    seen = frames_at_calls(replays.frames, rollouts.tokens.shape[1], chunk)
    if seen.shape[2:] != rollouts.observations.shape[2:]:
        raise ValueError(f"the replays' frames are {tuple(seen.shape[2:])}, the policy's observations "
                         f"{tuple(rollouts.observations.shape[2:])}: learning on replays needs the same views and size")
    return seen.contiguous()


def learning_batch(policy, batch: Rollouts, replayed: torch.Tensor, advantages: torch.Tensor, learn_on: str,
                   temperature: float, micro_batch: int, importance_cap: float = 0.0) -> tuple[Rollouts, torch.Tensor]:
    """The batch the update learns from, and its advantages.

    Args:
        batch: the kept rollouts, with the observations the policy acted on.
        replayed: (R, S, H, W, 3) the frames their replays showed at each call (`replay_observations`).
        advantages: (R,) or (R, S) the batch's advantages.
        learn_on: replays (each action held to its replay's frame) or both (held to both frames:
            every policy call is a row twice, so that the policy's proposals on the frames it acts on
            move with what it learns on the replays' frames).
        importance_cap: above 0, each token's advantage on the replay's frame is weighted by
            min(cap, p(token | replay's frame) / p(token | the frame it was sampled on)), both under
            the policy before the update (`importance_weights`); the advantages are then (R, S, N).
    """
    anchored = with_logp_on_observations(policy, dataclasses.replace(batch, observations=replayed), temperature,
                                         micro_batch)
    on_replays = advantages
    if importance_cap > 0:
        on_replays = per_token(advantages, batch.logp.shape) * importance_weights(anchored.logp, batch.logp,
                                                                                 batch.token_mask, importance_cap)
    if learn_on == "replays":
        return anchored, on_replays
    if learn_on == "both":
        own = per_token(advantages, batch.logp.shape) if importance_cap > 0 else advantages
        return concat_rollouts([batch, anchored]), torch.cat([own, on_replays])
    raise ValueError(f"learn_on must be replays or both here, got {learn_on!r}")


def with_logp_on_observations(policy, batch: Rollouts, temperature: float, micro_batch: int) -> Rollouts:
    """The batch with ``logp`` the policy's (as it is now) log-probabilities of its tokens on its
    observations: the reference the update's ratio starts from once the observations are not those
    the tokens were sampled on. Calls that executed nothing keep 0."""
    logp = torch.zeros_like(batch.logp)
    rows_r, rows_s = batch.token_mask.any(-1).nonzero(as_tuple=True)
    with torch.no_grad():
        for part in torch.arange(len(rows_r)).split(micro_batch):
            r, s = rows_r[part], rows_s[part]
            obs, texts, tokens, states = call_inputs(policy, batch, r, s)
            logp[r, s] = policy.log_prob(obs, texts, tokens, temperature, **states).float().cpu()
    return dataclasses.replace(batch, logp=logp)


def importance_weights(logp: torch.Tensor, sampled_logp: torch.Tensor, mask: torch.Tensor,
                       cap: float) -> torch.Tensor:
    """(R, S, N) min(cap, exp(logp - sampled_logp)) per token, 0 where `mask` is False: how much
    likelier the policy makes each token on the frame it is held to than on the one it was
    sampled on, truncated (as V-trace and Retrace truncate theirs) so that no token outweighs its
    advantage by more than `cap`."""
    ratio = torch.exp((logp - sampled_logp).clamp(max=math.log(cap)))
    return torch.where(mask, ratio, 0.0)


def per_token(advantages: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    """(R,) or (R, S) advantages spread to every token: (R, S, N)."""
    while advantages.ndim < len(shape):
        advantages = advantages[..., None]
    return advantages.expand(shape)
