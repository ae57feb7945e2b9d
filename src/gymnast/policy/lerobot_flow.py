"""LeRobot's flow-matching policies (SmolVLA) sampled as gymnast's flow VLA is: an SDE whose noise
a learned network sets, with the exact log-density of the sampled path.

SmolVLA integrates its action expert's velocity from noise at flow time 1 to actions at time 0 in
S Euler steps, ``x_{i+1} = x_i - v(x_i, 1 - i / S) / S``, over a (chunk_size, max_action_dim)
padded chunk, reading the image and instruction through a key-value cache computed once. gymnast
keeps that integration and adds Gaussian noise to each step (`gymnast.policy.flow_path`), with a
standard deviation from a noise network on the same features the velocity is read from (the
expert's output before ``action_out_proj``). Only the K x A elements gymnast executes get noise;
the padded action dimensions and the actions past K start at 0 and follow the mean, so they add
nothing to the density and the log-probability is exactly that of the executed elements' path.
The deterministic sampler (`act`) is LeRobot's own ``predict_action_chunk`` from zero noise.

Legend: B batch, S integration steps, P predicted actions (chunk_size), D padded action
dimensions (max_action_dim), K executed actions, A action dimensions, N = K * A.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import torch
from torch import nn

from gymnast.policy.base import ActionSample
from gymnast.policy.flow_path import bounded_sigma, init_noise_head, path_log_prob, sample_path
from gymnast.policy.lerobot_policy import ExplorationConfig, LeRobotPolicy

FLOW_TYPES = ("smolvla",)
"""LeRobot policy types sampled through the flow SDE (the others get a Gaussian head)."""


class LeRobotFlowPolicy(LeRobotPolicy):
    """A LeRobot flow-matching policy as a `gymnast.policy.base.Policy` (see the module docstring)."""

    def __init__(self, policy: nn.Module, preprocessor, postprocessor, files: dict, source: str,
                 exploration: ExplorationConfig) -> None:
        super().__init__(policy, preprocessor, postprocessor, files, source, exploration)
        config = policy.config
        if config.adapt_to_pi_aloha:
            raise ValueError(f"{source}: adapt_to_pi_aloha transforms the sampled actions outside the flow; "
                             "gymnast samples the flow itself, so it takes a policy without it")
        self.steps, self.padded = config.num_steps, config.max_action_dim
        expert = policy.model.action_out_proj
        self.noise = nn.Linear(expert.in_features, self.padded)
        init_noise_head(self.noise, exploration.sigma_min, exploration.sigma_init, exploration.sigma_max)
        # The velocity's own input features, captured as LeRobot's denoise_step computes them.
        self._features: list[torch.Tensor] = []
        expert.register_forward_pre_hook(lambda module, args: self._features.append(args[0]))
        noisy = torch.zeros(1, self.features.predicted, self.padded, dtype=torch.bool)
        noisy[:, : self.chunk_size, : self.action_dim] = True
        self.register_buffer("noisy", noisy, persistent=False)  # (1, P, D) the executed elements

    def mean_chunk(self, batch: dict[str, Any]) -> torch.Tensor:
        zeros = torch.zeros(len(batch[self.features.image_keys[0]]), self.features.predicted, self.padded,
                            device=self.device)
        chunk = self.policy.predict_action_chunk(batch, noise=zeros)
        self._features.clear()
        self.features.check_actions(chunk, self.source)
        return chunk

    # -- the Policy protocol ------------------------------------------------------------------------

    @torch.no_grad()
    def sample(self, obs: torch.Tensor, instructions: Sequence[str], temperature: float = 1.0,
               generator: torch.Generator | None = None, states: torch.Tensor | None = None) -> ActionSample:
        """A chunk from the stochastic sampler; ``tokens`` holds the executed elements' path (B, (S + 1) * N)."""
        if temperature <= 0:
            raise ValueError(f"temperature must be positive, got {temperature}; use act() for the deterministic sampler")
        transition = self._transition_for(self.inputs(obs, instructions, states))
        device = self.device

        def draw(shape: Sequence[int]) -> torch.Tensor:
            return torch.randn(tuple(shape), generator=generator,
                               device=generator.device if generator is not None else device).to(device)

        start = torch.where(self.noisy, draw((len(obs), self.features.predicted, self.padded)), 0.0)
        path = sample_path(transition, start, self.steps, temperature, draw, self.noisy)  # (B, S + 1, P, D)
        logp = path_log_prob(transition, path, self.steps, temperature, self.noisy)[0]
        executed = path[:, :, : self.chunk_size, : self.action_dim]  # (B, S + 1, K, A)
        return ActionSample(actions=self.to_actions(executed[:, -1]), tokens=executed.flatten(1).cpu(),
                            logp=self._executed(logp).cpu())

    def log_prob_and_entropy(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                             temperature: float = 1.0, states: torch.Tensor | None = None
                             ) -> tuple[torch.Tensor, torch.Tensor]:
        """`log_prob`, and the (B, N) entropy of each executed element's transitions along the path."""
        transition = self._transition_for(self.inputs(obs, instructions, states))
        logp, entropy = path_log_prob(transition, self._full_path(tokens), self.steps, temperature, self.noisy)
        return self._executed(logp), self._executed(entropy)

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, (S + 1) * N) a path ending at them (env units), zero before: the
        record of a greedy rollout, which is never trained on (its log-probabilities are zero)."""
        path = torch.zeros(len(actions), self.steps + 1, self.chunk_size, self.action_dim)
        path[:, -1] = actions.float()
        return path.flatten(1)

    # -- the SDE ------------------------------------------------------------------------------------

    def _transition_for(self, batch: dict[str, Any]):
        """The sampler's transition (`gymnast.policy.flow_path.Transition`) given a preprocessed
        batch: LeRobot's prefix (image, instruction, state) cached once, as its sampler does."""
        from lerobot.policies.smolvla.modeling_smolvla import make_att_2d_masks
        from lerobot.utils.constants import OBS_LANGUAGE_ATTENTION_MASK, OBS_LANGUAGE_TOKENS

        policy, model = self.policy, self.policy.model
        images, image_masks = policy.prepare_images(batch)
        prefix, prefix_pad, prefix_att = model.embed_prefix(images, image_masks, batch[OBS_LANGUAGE_TOKENS],
                                                             batch[OBS_LANGUAGE_ATTENTION_MASK],
                                                             state=policy.prepare_state(batch))
        _, cache = model.vlm_with_expert.forward(
            attention_mask=make_att_2d_masks(prefix_pad, prefix_att), position_ids=torch.cumsum(prefix_pad, dim=1) - 1,
            past_key_values=None, inputs_embeds=[prefix, None], use_cache=model.config.use_cache, fill_kv_cache=True)
        dt = -1.0 / self.steps  # from noise at time 1 to actions at time 0

        def transition(x: torch.Tensor, i: int) -> tuple[torch.Tensor, torch.Tensor]:
            time = torch.tensor(1.0 + i * dt, dtype=torch.float32, device=x.device).expand(len(x))
            self._features.clear()
            velocity = model.denoise_step(prefix_pad_masks=prefix_pad, past_key_values=cache, x_t=x, timestep=time)
            features = self._features.pop()  # (B, P, width) what action_out_proj read
            sigma = bounded_sigma(self.noise(features.float()), self.exploration.sigma_min, self.exploration.sigma_max)
            return x + dt * velocity, sigma

        return transition

    def _full_path(self, tokens: torch.Tensor) -> torch.Tensor:
        """(B, (S + 1) * N) recorded executed path -> (B, S + 1, P, D), zero elsewhere."""
        shape = (self.steps + 1, self.chunk_size, self.action_dim)
        if tokens.ndim != 2 or tokens.shape[1] != math.prod(shape):
            raise ValueError(f"a flow path must be (B, {math.prod(shape)}) = (B, (S + 1) * K * A), got {tuple(tokens.shape)}")
        path = torch.zeros(len(tokens), self.steps + 1, self.features.predicted, self.padded, device=self.device)
        path[:, :, : self.chunk_size, : self.action_dim] = tokens.float().view(len(tokens), *shape).to(self.device)
        return path

    def _executed(self, values: torch.Tensor) -> torch.Tensor:
        """(B, P, D) per element -> (B, N) the executed elements', chunk-major."""
        return values[:, : self.chunk_size, : self.action_dim].flatten(1)
