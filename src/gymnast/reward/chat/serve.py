"""`gymnast serve-judge`: the learned judge behind the OpenAI chat-completions protocol.

Many rollout workers (or any tool that speaks to VLMs) can then share one judge, and the VLM-judge
client is exercised end to end against a real server. The instruction is read from the rubric's
``Task:`` line (`gymnast.reward.chat.vlm.RUBRIC`), the frames from the request's images; the answer
ends with the line ``ANSWER: 1`` or ``ANSWER: 0`` the rubric asks for.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from gymnast.reward.chat.request import InvalidRequest
from gymnast.reward.chat.server import Answer, ChatLimits, ChatServer
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.train import load_judge
from gymnast.reward.judges.video import LearnedJudge

_TASK = re.compile(r"^Task:\s*(.+)$", re.MULTILINE)


def judge_server(run: Path, host: str = "127.0.0.1", port: int = 0, faults: Sequence[str] = (),
                 limits: ChatLimits = ChatLimits()) -> ChatServer:
    """A (not yet started) chat server answering with the judge trained in `run` (`faults`: see `ChatServer`)."""
    return ChatServer(judge_answer(load_judge(run)), host=host, port=port, faults=faults, model="gymnast-judge",
                      limits=limits)


def judge_answer(judge: LearnedJudge | FrameJudge) -> Answer:
    """The chat server's answer function for `judge`.

    A request the judge cannot read (no ``Task:`` line, no image, images of mixed sizes or of
    another size than the judge's) raises `InvalidRequest`, so the client gets a 400 naming the
    problem rather than a reply it would read as "could not score".
    """
    size = judge.config.image_size

    def answer(text: str, frames: list[np.ndarray]) -> str:
        task = _TASK.search(text)
        if task is None:
            raise InvalidRequest("the messages need a line 'Task: <instruction>' (see gymnast.reward.chat.vlm.RUBRIC)",
                                 "messages", "missing_task")
        if not frames:
            raise InvalidRequest("the messages need at least one image_url part: the video's frames", "messages",
                                 "missing_image")
        shapes = [frame.shape[:2] for frame in frames]
        if len(set(shapes)) > 1:
            odd = next(i for i, shape in enumerate(shapes) if shape != shapes[0])
            raise InvalidRequest(f"the images must all have one size: image 0 is {_size(shapes[0])} but image {odd} "
                                 f"is {_size(shapes[odd])}", "messages", "mixed_image_sizes")
        if shapes[0] != (size, size):
            raise InvalidRequest(f"this judge takes {size}x{size} images (width x height), got {_size(shapes[0])}; "
                                 "resize the frames before sending them", "messages", "wrong_image_size")
        video = torch.from_numpy(np.stack(frames))[None]  # (1, T, H, W, 3)
        probability = judge.probability(video, [task.group(1).strip()]).item()
        return f"P(success) = {probability:.3f}\nANSWER: {int(probability >= judge.config.threshold)}"

    return answer


def _size(shape: tuple[int, ...]) -> str:
    """'WxH' of an (H, W) shape."""
    return f"{shape[1]}x{shape[0]}"
