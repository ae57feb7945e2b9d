"""Stand-in world models of one's own for `gymnast check-wm`: one that keeps the contract, and one
per breach the check names. Tiny and deterministic unless a breach needs otherwise; importable as
``python:wm_stand_ins:FACTORY`` from these tests."""

from dataclasses import dataclass

import torch

from gymnast.world_model.base import check_actions, pad_context

SIZE, CONTEXT, WIDTH = 16, 2, 4


@dataclass(frozen=True)
class State:
    frames: torch.Tensor  # (B, C, H, W, 3) float in [0, 255]


class StandIn:
    """A frame is the last one brightened by the action's mean, plus a little noise from the generator."""

    context_frames, image_size, action_dim = CONTEXT, SIZE, WIDTH

    def init_state(self, context, generator=None):
        return State(pad_context(context, self.context_frames).float())

    def step(self, state, actions, generator=None):
        check_actions(actions, self.action_dim, len(state.frames))
        return self.roll(state, actions, generator)

    def roll(self, state, actions, generator):
        frames, last = [], state.frames[:, -1]
        for k in range(actions.shape[1]):
            last = self.next_frame(last, actions[:, k], generator)
            frames.append(last)
        video = torch.stack(frames, dim=1)  # (B, K, H, W, 3)
        return State(torch.cat([state.frames, video], dim=1)[:, -self.context_frames:]), self.output(video)

    def next_frame(self, last, action, generator):
        noise = torch.rand(last.shape, generator=generator) * 4
        return (last + 20 * action.mean(-1)[:, None, None, None] + noise).clamp(0, 255)

    def output(self, video):
        return video.round().to(torch.uint8)


class FloatFrames(StandIn):
    def output(self, video):
        return video / 255.0


class OtherSize(StandIn):
    def output(self, video):
        return super().output(video)[:, :, ::2, ::2]


class ChangesStateInPlace(StandIn):
    def step(self, state, actions, generator=None):
        new, frames = super().step(state, actions, generator)
        state.frames.copy_(new.frames)  # the given state moves on too
        return new, frames


class IgnoresGenerator(StandIn):
    def next_frame(self, last, action, generator):
        return super().next_frame(last, action, None) + torch.rand(last.shape) * 40


class OtherActionWidth(StandIn):
    action_dim = 3  # declared; the model takes 4-wide actions

    def step(self, state, actions, generator=None):
        if actions.shape[-1] != WIDTH:
            raise RuntimeError(f"mat1 and mat2 shapes cannot be multiplied ({actions.shape[-1]} and {WIDTH})")
        return self.roll(state, actions, generator)


class MixesRows(StandIn):
    def output(self, video):
        return super().output((video + video.mean(dim=0, keepdim=True)) / 2)


class RefusesShortContext(StandIn):
    def init_state(self, context, generator=None):
        if context.shape[1] < self.context_frames:
            raise ValueError(f"need {self.context_frames} context frames, got {context.shape[1]}")
        return super().init_state(context, generator)


class ForgetsOnload(StandIn):
    """Has offload() and onload(), but onload() brings back other weights."""

    gain = 20.0

    def offload(self):
        self.gain = None

    def onload(self):
        self.gain = 40.0

    def next_frame(self, last, action, generator):
        return (last + self.gain * action.mean(-1)[:, None, None, None]).clamp(0, 255)


def stand_in():
    return StandIn()


def float_frames():
    return FloatFrames()


def missing_parts():
    return object()
