"""A learned critic for `--credit critic`: PPO's value baseline beside GRPO's group baseline.

With per-call credit GRPO compares each policy call with its group's other rollouts at the same
call (`grpo.call_advantages`). In a group from one start those are nearly the same situation at the
first calls and drift apart as the rollouts diverge, so the later calls' baselines mix unlike
situations. A critic values the observation the call itself acted on, V(image, instruction), and
learns it across scenes and steps: each call's advantage is then generalised advantage estimation
(GAE, `grpo.gae_advantages`) of the calls' rewards against the critic's values.

The critic is the policy's own observation encoder (`ObservationConditioned`) and a small value
head, started from the policy's encoder weights where the policy has one (the embedded families),
so it sees what the policy learned to see; a LeRobot policy's critic starts from a small CNN. It is
fitted on every step's GAE targets after the advantages were computed, as PPO does, so a call's
value never comes from a fit to its own return.

Legend: R rollouts, S policy calls per rollout, M calls that acted, H/W image size, V views.
"""

from __future__ import annotations

import torch
from torch import nn

from gymnast.policy.observation import ObservationConditioned
from gymnast.rl import grpo
from gymnast.rl.rollout import Rollouts
from gymnast.utils.device import to_device


class ValueCritic(ObservationConditioned):
    """V(image, instruction): the expected reward-to-go of the call that acts on this observation.

    Args:
        vision: image encoder name (`gymnast.policy.vision.VISION_ENCODERS`).
        width: token width D.
        image_size: side of each view's square image.
        views: cameras V side by side in the input image.
    """

    def __init__(self, vision: str, width: int, image_size: int, views: int = 1) -> None:
        # No ImageNet weights are loaded here: `for_policy` copies the policy's encoder over them.
        super().__init__(vision, width, image_size, pretrained_vision=False, views=views)
        self.head = nn.Sequential(nn.LayerNorm(width), nn.Linear(width, width), nn.GELU(), nn.Linear(width, 1))

    @classmethod
    def for_policy(cls, policy) -> ValueCritic:
        """A critic that sees what `policy` sees (its image size and cameras), on its device,
        starting from its observation encoder's weights where it has one."""
        config = policy.config
        views = len(getattr(config, "cameras", ("front",)))
        own = isinstance(policy, ObservationConditioned)
        critic = cls(config.vision if own else "cnn", config.width if own else 128, config.image_size, views)
        if own:
            encoder = {name: value for name, value in policy.state_dict().items() if not name.startswith("head.")}
            wanted = critic.state_dict()
            critic.load_state_dict({name: value for name, value in encoder.items()
                                    if name in wanted and wanted[name].shape == value.shape}, strict=False)
        return critic.to(next(policy.parameters()).device)

    def forward(self, images: torch.Tensor, instructions: list[str]) -> torch.Tensor:
        """(B, H, V*W, 3) uint8 images and B instructions -> (B,) values."""
        memory = self.memory(images, self.embed_instructions(instructions, len(images)))  # (B, 1 + V*P, D)
        return self.head(memory.mean(dim=1)).squeeze(-1)


def explained_variance(targets: torch.Tensor, values: torch.Tensor) -> float:
    """1 - Var(targets - values) / Var(targets): 1 when the values foresaw the targets, 0 when they did
    no better than the targets' mean; NaN for fewer than two targets or targets that do not vary."""
    spread = targets.var() if len(targets) > 1 else torch.tensor(float("nan"))
    return (1 - (targets - values).var() / spread).item() if spread > 0 else float("nan")


class CallCritic:
    """The critic, its optimizer and what `rl_step` asks of them: advantages, then a fit.

    Args:
        critic: the value network.
        lr: its AdamW learning rate.
        epochs: passes over each step's calls when fitting.
        gae_lambda: GAE's lambda (1: the return minus the value; 0: one call's reward plus the next
            call's value minus this one's).
        micro_batch: calls per forward/backward pass.
        max_grad_norm: gradient clipping of each fitting step.
    """

    def __init__(self, critic: ValueCritic, lr: float, epochs: int, gae_lambda: float, micro_batch: int,
                 max_grad_norm: float = 1.0) -> None:
        self.critic, self.epochs, self.gae_lambda = critic, epochs, gae_lambda
        self.micro_batch, self.max_grad_norm = micro_batch, max_grad_norm
        self.optimizer = torch.optim.AdamW(critic.parameters(), lr=lr, weight_decay=0.0)

    def advantages_and_fit(self, batch: Rollouts, returns: torch.Tensor, normalize_std: bool,
                   generator: torch.Generator | None = None) -> tuple[torch.Tensor, dict[str, float]]:
        """(R, S) GAE advantages of the batch's calls from their (R, S) `grpo.reward_to_go`, then one
        fit of the critic on the calls' targets; returns them with the critic's metrics.

        ``critic/explained_variance`` is measured before the fit, on returns the critic has not seen:
        1 means its values foresaw them, 0 that it did no better than their mean.
        """
        acting = batch.token_mask.any(-1)  # (R, S)
        rows_r, rows_s = (acting & returns.isfinite()).nonzero(as_tuple=True)  # (M,) each
        values = torch.zeros(returns.shape)
        with torch.no_grad():
            self.critic.eval()
            for part in torch.arange(len(rows_r)).split(self.micro_batch):
                values[rows_r[part], rows_s[part]] = self._values(batch, rows_r[part], rows_s[part]).float().cpu()
        advantages, targets = grpo.gae_advantages(returns, values, acting, self.gae_lambda, normalize_std)
        chosen_targets, chosen_values = targets[rows_r, rows_s], values[rows_r, rows_s]
        metrics = {"critic/explained_variance": explained_variance(chosen_targets, chosen_values),
                   "critic/value_mean": chosen_values.mean().item() if len(chosen_values) else float("nan")}
        metrics["critic/loss"] = self._fit(batch, rows_r, rows_s, chosen_targets, generator)
        return advantages, metrics

    def _values(self, batch: Rollouts, r: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        return self.critic(batch.observations[r, s], [batch.instructions[i] for i in r.tolist()])

    def _fit(self, batch: Rollouts, rows_r: torch.Tensor, rows_s: torch.Tensor, targets: torch.Tensor,
             generator: torch.Generator | None) -> float:
        """`epochs` passes of shuffled micro-batches of mean squared error; the last pass's mean loss."""
        self.critic.train()
        loss_sum, count = 0.0, 0
        for epoch in range(self.epochs):
            loss_sum, count = 0.0, 0
            for part in torch.randperm(len(rows_r), generator=generator).split(self.micro_batch):
                predicted = self._values(batch, rows_r[part], rows_s[part]).float()
                loss = nn.functional.mse_loss(predicted, to_device(targets[part], predicted.device))
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(self.critic.parameters(), self.max_grad_norm)
                self.optimizer.step()
                loss_sum, count = loss_sum + loss.item() * len(part), count + len(part)
        return loss_sum / count if count else float("nan")

    def state_dict(self) -> dict:
        """The critic's weights and optimizer state, for the run's checkpoints (`--resume`)."""
        return {"critic": self.critic.state_dict(), "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.critic.load_state_dict(state["critic"])
        self.optimizer.load_state_dict(state["optimizer"])
