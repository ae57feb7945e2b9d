"""A frozen image encoder's work done once per observation in an RL step.

An RL step with the image encoder frozen (`RLConfig.freeze`, vision by default) encodes every
observation the policy acted on up to three times: when the policy samples its action, again in the
update's log-probabilities, and again in the frozen reference policy's (the KL penalty), although
the encoder, fixed, gives the same tokens each time. On a CPU the encoder is the largest part of a
policy call, so `remembered_vision` keeps what it computed for each observation while a step runs
and hands it back when the same image comes again. Only the encoder's own output is kept: what
follows it (the instruction's modulation, the state's token, the decoder) is computed as before,
so gradients flow exactly as without it.

An image is known by a digest of its bytes, so the same observation drawn again (a group's G
rollouts start from one frame) is found whichever tensor holds it. Images on an accelerator are
encoded as before: there the encoder is cheap and reading them back to the host to name them is not.

Legend: B images, H/W one view's size, V views, P vision tokens per view, D width.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import torch
from torch import nn


class VisionMemory:
    """The tokens an encoder computed for each image it saw, by the image's bytes."""

    def __init__(self) -> None:
        self.tokens: dict[bytes, torch.Tensor] = {}
        self.hits = self.misses = 0

    def encode(self, images: torch.Tensor, bf16: bool, encode: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor:
        """(B, H, V*W, 3) uint8 host images -> their (B*V, P, D) tokens, as `encode` (images -> tokens,
        the views flattened into the batch) gives them, computing only the images not seen before
        with the same `bf16` setting."""
        keys = [_digest(image, bf16) for image in images]
        new = list(dict.fromkeys(key for key in keys if key not in self.tokens))
        if new:
            first = {key: i for i, key in reversed(list(enumerate(keys)))}
            fresh = encode(images[[first[key] for key in new]]).detach()  # (N*V, P, D)
            for key, tokens in zip(new, fresh.chunk(len(new))):
                self.tokens[key] = tokens
        self.misses += len(new)
        self.hits += len(keys) - len(new)
        return torch.cat([self.tokens[key] for key in keys])


def _digest(image: torch.Tensor, bf16: bool) -> bytes:
    return hashlib.blake2b(image.contiguous().numpy().tobytes(), digest_size=16, person=b"bf16" if bf16 else b"").digest()


def frozen_encoder(policy: object) -> nn.Module | None:
    """The policy's image encoder where it is an embedded policy's and no parameter of it learns."""
    encoder = getattr(policy, "vision", None)
    if not isinstance(encoder, nn.Module) or not hasattr(policy, "vision_memory"):
        return None
    parameters = list(encoder.parameters())
    return encoder if parameters and not any(p.requires_grad for p in parameters) else None


@contextmanager
def remembered_vision(*policies: object) -> Iterator[list[VisionMemory]]:
    """While inside, each embedded policy with a frozen image encoder encodes an image once; policies
    whose encoders hold the same weights (an RL policy and its frozen reference) share what was
    computed. Yields the memories (for their hit counts); forgets everything on leaving."""
    shared: list[tuple[nn.Module, VisionMemory]] = []
    chosen = []
    for policy in policies:
        encoder = frozen_encoder(policy)
        if encoder is None:
            continue
        memory = next((m for other, m in shared if _same_weights(encoder, other)), None)
        if memory is None:
            memory = VisionMemory()
            shared.append((encoder, memory))
        chosen.append((policy, memory))
    try:
        for policy, memory in chosen:
            policy.vision_memory = memory
        yield [memory for _, memory in shared]
    finally:
        for policy, _ in chosen:
            policy.vision_memory = None


def _same_weights(a: nn.Module, b: nn.Module) -> bool:
    mine, theirs = a.state_dict(), b.state_dict()
    return mine.keys() == theirs.keys() and all(
        mine[k].shape == theirs[k].shape and mine[k].device == theirs[k].device and torch.equal(mine[k], theirs[k])
        for k in mine)
