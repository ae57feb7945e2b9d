"""The per-frame success judge: is the task done in this frame?

Legend: B videos, T frames, N judged frames, H/W image size, V cameras, D feature width.

Meta-World reports success at every step, so a judge can learn from every frame of every
episode (tens of thousands of labelled frames where whole-episode labels give a few hundred
videos), and it can judge a video the way the real world does: a rollout succeeds if the task is
done at any step. Each frame is judged beside the video's first frame (where the objects and the
goal started, which a frame alone may hide behind the arm) and the instruction's MiniLM
embedding; the video's probability of success is that of its most convincing run of
`JudgeConfig.hold_steps` frames in a row, a run as convincing as its least convincing frame (the
start frame excluded: nothing has been done yet). With one frame, a single frame that the frames
around it deny is enough for a false success; Meta-World's successes last.

Several cameras arrive side by side in each frame (`gymnast.utils.images.tile_views`): each
camera's pair of squares goes through the same encoder alone, and the head reads the V features
one after the other, so it knows which camera saw what.

The decision threshold is part of the model's settings, chosen by `gymnast train-judge` on
validation scenes that neither training nor the reported figures use.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from gymnast.policy.text import EMBEDDING_DIM, InstructionEncoder
from gymnast.policy.vision import to_float_image
from gymnast.reward.judges.base import JudgeConfig, ThresholdJudge, check_videos, labelled_loss
from gymnast.utils.device import bf16_autocast, to_device
from gymnast.utils.images import changed_frames, latest_changed, split_views

FRAMES_PER_PASS = 512  # frames through the CNN at once: bounds memory on long batches of videos


def _pair_encoder(width: int) -> nn.Sequential:
    """(N, 6, H, W) first frame and judged frame, stacked -> (N, width) features.

    The two frames enter together so the first layers can see what changed, and the final grid is
    kept (flattened), not pooled: success is a spatial relation (the puck *at* the goal), which
    pooling would blur. Lighter than the policy's CNN because a judge scores every frame.
    """
    layers, channels = [], 6
    for out in (32, 64, 64, 64):
        layers += [nn.Conv2d(channels, out, 3, stride=2, padding=1), nn.GroupNorm(8, out), nn.GELU()]
        channels = out
    return nn.Sequential(*layers, nn.Flatten(), nn.LazyLinear(width), nn.GELU())


class FrameJudge(ThresholdJudge, nn.Module):
    """`Reward` whose score is 1.0 when some frame after the first shows success (P >= threshold)."""

    backend = "frame-judge"

    def __init__(self, config: JudgeConfig = JudgeConfig()) -> None:
        super().__init__()
        self.config = config
        self.views = len(config.cameras)
        self.vision = _pair_encoder(config.width)
        self.text = nn.Linear(EMBEDDING_DIM, config.width)
        self.head = nn.Sequential(nn.Linear((self.views + 1) * config.width, 256), nn.GELU(), nn.Linear(256, 1))
        self.encoder = InstructionEncoder()
        blank = torch.zeros(1, config.image_size, self.views * config.image_size, 3, dtype=torch.uint8)
        self(blank, blank, torch.zeros(1, EMBEDDING_DIM))  # sizes the lazy layer

    def forward(self, first: torch.Tensor, frames: torch.Tensor, text: torch.Tensor) -> torch.Tensor:
        """(N, H, V*W, 3) uint8 first frames and judged frames, (N, 384) embeddings -> (N,) logits."""
        size, views = self.config.image_size, self.views
        if tuple(frames.shape[1:]) != (size, views * size, 3) or first.shape != frames.shape:
            raise ValueError(f"a judge of cameras {','.join(self.config.cameras)} needs (N, {size}, {views * size}, 3) "
                             f"frames (the cameras side by side), got {tuple(frames.shape)} and first frames {tuple(first.shape)}")
        logits = []
        for start in range(0, len(frames), FRAMES_PER_PASS):
            part = slice(start, start + FRAMES_PER_PASS)
            device = self.text.weight.device
            squares = [to_float_image(split_views(to_device(images[part], device), self.views)) for images in (first, frames)]
            pair = torch.cat(squares, dim=1) * 2.0 - 1.0  # (n*V, 6, H, W)
            with bf16_autocast(device):  # ~2x faster convolutions where bf16 is native
                image = self.vision(pair).float().reshape(len(pair) // self.views, -1)  # (n, V*D)
            logits.append(self.head(torch.cat([image, self.text(to_device(text[part], device))], dim=1)).squeeze(1))
        return torch.cat(logits)

    @torch.no_grad()
    def frame_probabilities(self, videos: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        """(B, T) P(success shows in frame t) for (B, T, H, W, 3) uint8 videos; frame 0 gets 0."""
        check_videos(videos, instructions)
        batch, length = videos.shape[:2]
        if length < 2:
            return torch.zeros(batch, length)
        later = videos[:, 1:]  # (B, T-1, H, W, 3)
        # A frame equal to the one before it gets its probability, not another pass: a world model of
        # one frame per chunk repeats each frame for the chunk's other actions, and a video repeats
        # its last frame after the episode ends.
        new = changed_frames(later)
        first = videos[:, :1].expand(-1, length - 1, -1, -1, -1)[new]
        text = self.encoder(instructions)[:, None].expand(-1, length - 1, -1)[new]
        judged = torch.sigmoid(self(first, later[new], text).float()).cpu()  # (N,) one per new frame
        probabilities = torch.zeros(batch, length - 1)
        probabilities[new] = judged
        return torch.cat([torch.zeros(batch, 1), probabilities.gather(1, latest_changed(new))], dim=1)

    def probability(self, videos: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        """(B,) P(success) of each video: that of its most convincing run of `hold_steps` frames."""
        return self.video_probability(self.frame_probabilities(videos, instructions))

    def video_probability(self, frame_probabilities: torch.Tensor) -> torch.Tensor:
        """(B,) P(success) of videos from their (B, T) `frame_probabilities` (frame 0 at 0)."""
        return held_probability(frame_probabilities, self.config.hold_steps)


def held_probability(frame_probabilities: torch.Tensor, steps: int) -> torch.Tensor:
    """(B,) the largest over t of the smallest of (B, T) per-frame probabilities over frames t to
    t + steps - 1; a run cut by the video's end is held by its last frame (nothing shows it undone)."""
    if steps == 1:
        return frame_probabilities.max(dim=1).values
    held = torch.cat([frame_probabilities, frame_probabilities[:, -1:].expand(-1, steps - 1)], dim=1)  # (B, T+steps-1)
    return held.unfold(1, steps, 1).min(dim=2).values.max(dim=1).values  # windows (B, T, steps)


def frame_loss(judge: FrameJudge, first: torch.Tensor, frames: torch.Tensor, text: torch.Tensor, labels: torch.Tensor):
    """Binary cross-entropy of (N, H, W, 3) frames, beside their videos' (N, H, W, 3) first frames,
    against (N,) labels; (loss, metrics)."""
    return labelled_loss(judge(first, frames, text), labels)
