"""Stand-in policies of one's own for `gymnast check-policy`: the example package's policy, which
keeps the contract, and one per breach the check names; importable as
``python:policy_stand_ins:FACTORY`` from these tests."""

import dataclasses

import torch

from tiny_video_wm.policy import TinyPolicy, TinyPolicyConfig

SMALL = TinyPolicyConfig(image_size=32, chunk_size=3, bins=8, width=16)


def small() -> TinyPolicy:
    torch.manual_seed(0)
    return TinyPolicy(SMALL).eval()


class ForgetsTheTemperature(TinyPolicy):
    def log_prob(self, obs, instructions, tokens, temperature=1.0):
        return super().log_prob(obs, instructions, tokens, 1.0)

    def log_prob_and_entropy(self, obs, instructions, tokens, temperature=1.0):
        return super().log_prob_and_entropy(obs, instructions, tokens, 1.0)


class SamplesWhenGreedy(TinyPolicy):
    def act(self, obs, instructions):
        return self.sample(obs, instructions).actions


class DeclaresAnotherChunk(TinyPolicy):
    def __init__(self, config: TinyPolicyConfig = SMALL) -> None:
        super().__init__(config)
        self.chunk_size = config.chunk_size + 1  # declared; it makes config.chunk_size actions

    def _decode(self, tokens):
        return self.centres[tokens].view(len(tokens), self.config.chunk_size, self.action_dim)


class IgnoresTheGenerator(TinyPolicy):
    def sample(self, obs, instructions, temperature=1.0, generator=None):
        return super().sample(obs, instructions, temperature, None)


class ReadsNoStateItDeclares(TinyPolicy):
    state_dim = 3

    def sample(self, obs, instructions, temperature=1.0, generator=None, states=None):
        return super().sample(obs, instructions, temperature, generator)

    def log_prob(self, obs, instructions, tokens, temperature=1.0, states=None):
        return super().log_prob(obs, instructions, tokens, temperature)

    def log_prob_and_entropy(self, obs, instructions, tokens, temperature=1.0, states=None):
        return super().log_prob_and_entropy(obs, instructions, tokens, temperature)

    def act(self, obs, instructions, states=None):
        return super().act(obs, instructions)


def make(cls: type[TinyPolicy]) -> TinyPolicy:
    torch.manual_seed(0)
    return cls(dataclasses.replace(SMALL)).eval()


def forgets_the_temperature() -> TinyPolicy:
    return make(ForgetsTheTemperature)
