"""`gymnast check-policy`: does a policy keep the `Policy` contract that RL and evaluation rely on?

Legend: B batch, H/W image size (W: the V cameras side by side), K chunk, A action dimensions,
N tokens of a chunk, D robot state dimensions.

`check_policy` calls the policy on synthetic camera images and instructions as gymnast does
(host tensors, a host generator) and returns every breach it finds, each with what to change.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

from gymnast.policy.load import REQUIRED
from gymnast.utils.plugins import Breach

LOGP_TOLERANCE = 1e-4
"""How far `log_prob` may be from the sampled `logp` (float32 recomputation, not another distribution)."""
TEMPERATURE = 0.8
"""The sampling temperature checked: not 1, so a `log_prob` that forgets it is caught."""
INSTRUCTIONS = ("reach the goal", "push the puck to the goal", "open the drawer", "close the window")


class _Stop(Exception):
    def __init__(self, breach: Breach) -> None:
        super().__init__(breach.message)
        self.breach = breach


def check_policy(policy: Any, batch: int = 2, seed: int = 0) -> list[Breach]:
    """Every breach of the `Policy` contract found by calling `policy`; empty when it keeps it.

    Args:
        policy: the policy (anything `gymnast.policy.load.load_policy` returns).
        batch: B of the calls.
        seed: of the synthetic inputs and of the generators passed to the policy.
    """
    missing = [name for name in REQUIRED if not hasattr(policy, name)]
    if not missing and not hasattr(policy.config, "image_size"):
        missing = ["config.image_size"]
    if missing:
        return [Breach("attributes", f"the policy lacks {', '.join(missing)}: a policy has chunk_size and action_dim "
                                     "(ints), state_dim (0 when it reads no state), a config with the image_size it "
                                     "sees, and sample, log_prob, log_prob_and_entropy, chunk_tokens and act "
                                     "(gymnast.policy.base.Policy)")]
    breaches: list[Breach] = []
    try:
        _Checker(policy, batch, seed, breaches).run()
    except _Stop as stop:
        breaches.append(stop.breach)
    return breaches


class _Checker:
    def __init__(self, policy: Any, batch: int, seed: int, breaches: list[Breach]) -> None:
        self.policy, self.breaches, self.seed = policy, breaches, seed
        inputs = torch.Generator().manual_seed(seed)
        size = policy.config.image_size
        views = max(1, len(getattr(policy.config, "cameras", ()) or ()))
        self.obs = torch.randint(0, 256, (batch, size, views * size, 3), generator=inputs, dtype=torch.uint8)
        self.instructions = [INSTRUCTIONS[b % len(INSTRUCTIONS)] for b in range(batch)]
        self.state_dim = int(getattr(policy, "state_dim", 0))
        self.states = torch.randn(batch, self.state_dim, generator=inputs) if self.state_dim else None  # (B, D)
        self.chunk = (batch, policy.chunk_size, policy.action_dim)  # (B, K, A)

    def _inputs(self) -> dict[str, torch.Tensor]:
        return {} if self.states is None else {"states": self.states}

    def _call(self, what: str, call: Callable[[], Any]) -> Any:
        try:
            with torch.no_grad():
                return call()
        except Exception as error:  # the user's code may raise anything; the breach names it
            raise _Stop(Breach("call", f"{what} raised {type(error).__name__}: {error}; gymnast calls it with obs "
                                       f"{tuple(self.obs.shape)} uint8 (the cameras side by side), {len(self.obs)} "
                                       "instruction strings" + (f" and states (B, {self.state_dim})" if self.states is
                                                                 not None else ""))) from error

    def sample(self, seed_offset: int = 1) -> Any:
        generator = torch.Generator().manual_seed(self.seed + seed_offset)
        return self._call("sample(obs, instructions, temperature, generator)", lambda: self.policy.sample(
            self.obs, self.instructions, TEMPERATURE, generator, **self._inputs()))

    def run(self) -> None:
        self.state_input()
        drawn = self.sample()
        self.sample_shapes(drawn)
        self.log_prob(drawn)
        self.generator(drawn)
        self.greedy()

    def state_input(self) -> None:
        if not self.state_dim:
            return
        try:
            with torch.no_grad():
                self.policy.act(self.obs, self.instructions)
        except ValueError:
            return  # refused without the state it reads, as the contract asks
        except Exception as error:
            self.breaches.append(Breach("state", f"act() without states raised {type(error).__name__}: {error}; a policy "
                                        f"with state_dim={self.state_dim} raises ValueError when states is None, saying "
                                        "it needs the robot's state"))
            return
        self.breaches.append(Breach("state", f"act() ran without the robot's state though state_dim={self.state_dim}: "
                                    "gymnast gives states (B, D) only to a policy whose state_dim > 0, so a policy that "
                                    "reads one raises ValueError without it, and one that does not declares state_dim 0"))

    def sample_shapes(self, drawn: Any) -> None:
        fields = [name for name in ("actions", "tokens", "logp") if not isinstance(getattr(drawn, name, None), torch.Tensor)]
        if fields:
            raise _Stop(Breach("sample", f"sample() returned a {type(drawn).__name__} without tensor(s) {', '.join(fields)}: "
                                         "return gymnast.policy.base.ActionSample(actions, tokens, logp)"))
        if tuple(drawn.actions.shape) != self.chunk or not drawn.actions.is_floating_point():
            self.breaches.append(Breach("action_shape", f"sample() returned actions {tuple(drawn.actions.shape)} "
                                        f"{drawn.actions.dtype}, expected {self.chunk} float (B, chunk_size, action_dim): "
                                        "declare the chunk_size and action_dim the policy makes"))
        if drawn.tokens.ndim < 2 or drawn.tokens.shape[0] != len(self.obs):
            self.breaches.append(Breach("tokens", f"sample() returned tokens {tuple(drawn.tokens.shape)}, expected "
                                        f"({len(self.obs)}, N): a row per batch element, what log_prob scores"))

    def log_prob(self, drawn: Any) -> None:
        again = self._call("log_prob(obs, instructions, tokens, temperature)", lambda: self.policy.log_prob(
            self.obs, self.instructions, drawn.tokens, TEMPERATURE, **self._inputs()))
        both = self._call("log_prob_and_entropy(obs, instructions, tokens, temperature)", lambda: self.policy.log_prob_and_entropy(
            self.obs, self.instructions, drawn.tokens, TEMPERATURE, **self._inputs()))
        for name, value in (("log_prob", again), ("log_prob_and_entropy", both[0] if isinstance(both, tuple) else both)):
            if not isinstance(value, torch.Tensor) or value.shape != drawn.logp.shape:
                got = tuple(value.shape) if isinstance(value, torch.Tensor) else type(value).__name__
                self.breaches.append(Breach("log_prob", f"{name}() of the sampled tokens gave {got}, sample()'s logp is "
                                            f"{tuple(drawn.logp.shape)}: both score each sampled token"))
                continue
            gap = (value.detach().float().cpu() - drawn.logp.float().cpu()).abs().max().item()
            if not gap <= LOGP_TOLERANCE:
                self.breaches.append(Breach("log_prob", f"{name}() of the tokens sample() drew differs from the logp it "
                                            f"returned by up to {gap:.3g} at temperature {TEMPERATURE}: GRPO's ratio "
                                            "exp(log_prob - logp) must start at 1, so compute both from the same "
                                            "distribution (the logits divided by the temperature), in float32"))

    def generator(self, drawn: Any) -> None:
        again = self.sample()
        if not torch.equal(drawn.actions, again.actions):
            self.breaches.append(Breach("generator", "two samples with generators seeded alike drew different actions: "
                                        "draw every random number from the generator passed to sample() "
                                        "(torch.rand(..., generator=generator)), not torch's global random state"))

    def greedy(self) -> None:
        first, second = (self._call("act(obs, instructions)", lambda: self.policy.act(
            self.obs, self.instructions, **self._inputs())) for _ in range(2))
        if not isinstance(first, torch.Tensor) or tuple(first.shape) != self.chunk:
            got = tuple(first.shape) if isinstance(first, torch.Tensor) else type(first).__name__
            self.breaches.append(Breach("action_shape", f"act() returned {got}, expected {self.chunk} (B, chunk_size, "
                                        "action_dim): declare the chunk_size and action_dim the policy makes"))
            return
        if not torch.equal(first, second):
            self.breaches.append(Breach("act_deterministic", "act() gave two different chunks for the same input: act is "
                                        "greedy (the most likely chunk: argmax, or the mean), what evaluation runs; "
                                        "sample() is where randomness belongs"))
