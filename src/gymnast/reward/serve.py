"""`gymnast serve-judge`: the learned judge behind the OpenAI chat-completions protocol.

Many rollout workers (or any tool that speaks to VLMs) can then share one judge, and the VLM-judge
client is exercised end to end against a real server. The instruction is read from the rubric's
``Task:`` line (`gymnast.reward.vlm.RUBRIC`), the frames from the request's images; the answer
ends with the line ``ANSWER: 1`` or ``ANSWER: 0`` the rubric asks for.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from gymnast.reward.chat_server import ChatServer
from gymnast.reward.train_judge import load_judge

_TASK = re.compile(r"^Task:\s*(.+)$", re.MULTILINE)


def judge_server(run: Path, host: str = "127.0.0.1", port: int = 0, faults: Sequence[str] = ()) -> ChatServer:
    """A (not yet started) chat server answering with the judge trained in `run` (`faults`: see `ChatServer`)."""
    judge = load_judge(run)

    def answer(text: str, frames: list[np.ndarray]) -> str:
        task = _TASK.search(text)
        if task is None or not frames:
            return "I need a 'Task: ...' line and at least one image."  # no ANSWER line: the client reads NaN
        video = torch.from_numpy(np.stack(frames))[None]  # (1, T, H, W, 3)
        if video.shape[2:4] != (judge.config.image_size, judge.config.image_size):
            return f"Images must be {judge.config.image_size}x{judge.config.image_size}, got {tuple(video.shape[2:4])}."
        probability = judge.probability(video, [task.group(1).strip()]).item()
        return f"P(success) = {probability:.3f}\nANSWER: {int(probability >= 0.5)}"

    return ChatServer(answer, host=host, port=port, faults=faults, model="gymnast-judge")
