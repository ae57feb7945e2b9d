"""The embedded vision-language-action model: a small VLA that trains on a laptop CPU.

Image -> a grid of vision tokens conditioned on the instruction (`gymnast.policy.observation`);
K x A learned action queries attend to those tokens and to each other
through a small transformer decoder without a causal mask, so the whole chunk is decoded in
parallel in one forward pass, as in OpenVLA-OFT. Each query ends in a 256-way categorical over
its action dimension's bins.

Legend: B batch, H/W image size (W: every camera's side by side), K chunk length, A action
dimensions, N = K * A tokens, P vision tokens (of all cameras), D width, V bins.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from gymnast.policy.action_tokenizer import ActionTokenizer
from gymnast.policy.base import ActionSample
from gymnast.policy.observation import ObservationConditioned, PolicyArchitecture


@dataclass(frozen=True)
class VLAConfig(PolicyArchitecture):
    """Architecture of the embedded VLA."""

    bins: int = 256
    """Tokens per action dimension."""

    @property
    def num_tokens(self) -> int:
        return self.chunk_size * self.action_dim


class EmbeddedVLA(ObservationConditioned):
    """The `Policy` implementation shipped with gymnast (see `gymnast.policy.base.Policy`).

    Args:
        config: architecture.
        tokenizer: action binning; saved with the weights.
        pretrained_vision: load ImageNet weights for the efficientnet encoder.
    """

    def __init__(self, config: VLAConfig, tokenizer: ActionTokenizer | None = None, pretrained_vision: bool = True) -> None:
        tokenizer = tokenizer or ActionTokenizer(bins=config.bins)
        if tokenizer.action_dim != config.action_dim or tokenizer.bins != config.bins:
            raise ValueError(
                f"tokenizer has {tokenizer.action_dim} dims x {tokenizer.bins} bins, "
                f"config wants {config.action_dim} x {config.bins}"
            )
        super().__init__(config.vision, config.width, config.image_size, pretrained_vision, len(config.cameras),
                         config.state_dim)
        self.config, self.tokenizer = config, tokenizer
        self.chunk_size, self.action_dim = config.chunk_size, config.action_dim
        self.queries = nn.Parameter(torch.randn(1, config.num_tokens, config.width) * 0.02)
        layer = nn.TransformerDecoderLayer(
            config.width, config.heads, dim_feedforward=2 * config.width, dropout=0.0, batch_first=True, norm_first=True
        )
        self.decoder = nn.TransformerDecoder(layer, config.layers)
        self.norm = nn.LayerNorm(config.width)
        self.head = nn.Linear(config.width, config.bins)

    # -- the network -----------------------------------------------------------------------------

    def forward(self, images: torch.Tensor, text: torch.Tensor, bf16_vision: bool = False,
                states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, H, W, 3) uint8 images (W: the views side by side), (B, 384) instruction embeddings and
        the (B, S) robot states of a policy that reads them -> (B, N, V) logits."""
        memory = self.memory(images, text, bf16_vision, states)  # (B, 1 + P, D), one more with a state
        queries = self.queries.expand(len(images), -1, -1)  # (B, N, D)
        return self.head(self.norm(self.decoder(queries, memory)))

    def logits(self, obs: torch.Tensor, instructions: Sequence[str], bf16_vision: bool = False,
               states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, N, V) action-token logits for images and their instructions (and states)."""
        return self(obs, self.embed_instructions(instructions, len(obs)), bf16_vision, states)

    # -- the Policy protocol ------------------------------------------------------------------------

    @torch.no_grad()
    def sample(
        self,
        obs: torch.Tensor,
        instructions: Sequence[str],
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
        states: torch.Tensor | None = None,
    ) -> ActionSample:
        if temperature <= 0:
            raise ValueError(f"temperature must be positive, got {temperature}; use act() for greedy actions")
        log_probs = torch.log_softmax(self.logits(obs, instructions, states=states).float() / temperature, dim=-1)
        flat = log_probs.flatten(0, 1).exp()  # (B * N, V)
        tokens = self._draw(flat, generator).view(log_probs.shape[:2])  # (B, N)
        logp = log_probs.gather(-1, tokens.unsqueeze(-1)).squeeze(-1)
        return ActionSample(actions=self._decode(tokens), tokens=tokens.cpu(), logp=logp.cpu())

    def log_prob(
        self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor, temperature: float = 1.0,
        states: torch.Tensor | None = None,
    ) -> torch.Tensor:
        log_probs = torch.log_softmax(self.logits(obs, instructions, states=states).float() / temperature, dim=-1)
        return log_probs.gather(-1, tokens.to(log_probs.device).unsqueeze(-1)).squeeze(-1)  # (B, N)

    def log_prob_and_entropy(
        self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor, temperature: float = 1.0,
        states: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        log_probs = torch.log_softmax(self.logits(obs, instructions, states=states).float() / temperature, dim=-1)
        entropy = -(log_probs.exp() * log_probs).sum(-1)  # (B, N)
        return log_probs.gather(-1, tokens.to(log_probs.device).unsqueeze(-1)).squeeze(-1), entropy

    @torch.no_grad()
    def act(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None = None) -> torch.Tensor:
        return self._decode(self.logits(obs, instructions, states=states).argmax(-1))

    def _decode(self, tokens: torch.Tensor) -> torch.Tensor:
        """(B, N) tokens -> (B, K, A) actions on the host."""
        return self.tokenizer.decode(tokens.cpu().view(len(tokens), self.chunk_size, self.action_dim))

    @staticmethod
    def _draw(probabilities: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """(M, V) probabilities -> (M, 1) draws by inverting each row's cumulative sum at one
        uniform number from `generator` (on its device, the host's by default), where the
        probabilities are. One number a row instead of torch.multinomial's V: with an RL run's
        host generator and the policy on a GPU, multinomial moved every probability to the host and
        drew 256 exponentials a token there, most of the policy's sampling time (BENCHMARKS.md)."""
        device = generator.device if generator is not None else probabilities.device
        uniform = torch.rand(len(probabilities), 1, generator=generator, device=device).to(probabilities.device)
        cumulative = probabilities.cumsum(-1)
        # right=True: the first token whose cumulative sum exceeds the point, never one of zero probability.
        drawn = torch.searchsorted(cumulative, uniform * cumulative[:, -1:], right=True)
        return drawn.clamp_(max=probabilities.shape[-1] - 1)

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> (B, N) tokens (the SFT targets)."""
        return self.tokenizer.encode(actions).flatten(1)

    # -- supervised learning ------------------------------------------------------------------------

    def imitation_loss(self, images: torch.Tensor, texts: Sequence[str], chunks: torch.Tensor, valid: torch.Tensor,
                       bf16: bool = False, generator: torch.Generator | None = None,
                       states: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
        """SFT's loss on expert chunks (B, K, A) with their (B, K) validity (and the (B, S) states
        they were taken in, for a policy that reads them): the masked token cross-entropy, and
        metrics. Nothing is drawn, so `generator` is unused."""
        logits = self.logits(images, texts, bf16_vision=bf16, states=states)  # (B, N, V)
        targets = self.chunk_tokens(chunks).to(logits.device)  # (B, N)
        mask = valid.repeat_interleave(self.action_dim, dim=1).float().to(logits.device)  # (B, N): chunk-major like the tokens
        per_token = F.cross_entropy(logits.transpose(1, 2), targets, reduction="none")  # (B, N)
        loss = (per_token * mask).sum() / mask.sum()
        accuracy = ((logits.argmax(-1) == targets).float() * mask).sum() / mask.sum()
        return loss, {"train/loss": loss.item(), "train/token_accuracy": accuracy.item()}

    # -- persistence --------------------------------------------------------------------------------

    def spec(self) -> dict:
        """What rebuilds this model: architecture and tokenizer (saved as config.json)."""
        return {"vla": dataclasses.asdict(self.config), "tokenizer": self.tokenizer.to_dict()}

    @classmethod
    def from_spec(cls, spec: dict) -> EmbeddedVLA:
        # The ImageNet weights are replaced by the checkpoint's right after, so skip loading them.
        return cls(VLAConfig(**spec["vla"]), ActionTokenizer.from_dict(spec["tokenizer"]), pretrained_vision=False)
