"""`gymnast serve-judge`: the learned judge behind the OpenAI chat-completions protocol.

Many rollout workers (or any tool that speaks to VLMs) can then share one judge, and the VLM-judge
client is exercised end to end against a real server. The instruction is read from the rubric's
``Task:`` line (`gymnast.reward.chat.vlm.RUBRIC`), the frames from the request's images; the answer
ends with the line ``ANSWER: 1`` or ``ANSWER: 0`` the rubric asks for.

A judge of V cameras at S px scores frames of its views side by side (S x V*S, the primary first,
as `gymnast.utils.images.tile_views` makes them). A request may send each instant that way, or as
V images of S x S, one per camera: in the judge's order instant by instant, or each camera's images
after a text line ``Camera: NAME`` (`gymnast.reward.chat.request`). `GET /v1/models` says which
(`judge_card`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from gymnast.reward.chat.request import ChatRequest, InvalidRequest
from gymnast.reward.chat.server import Answer, ChatLimits, ChatServer
from gymnast.reward.judges.base import JudgeConfig, ThresholdJudge
from gymnast.reward.judges.train import load_judge

_TASK = re.compile(r"^Task:\s*(.+)$", re.MULTILINE)


def judge_server(run: Path, host: str = "127.0.0.1", port: int = 0, faults: Sequence[str] = (),
                 limits: ChatLimits = ChatLimits(), api_key: str | None = None) -> ChatServer:
    """A (not yet started) chat server answering with the judge trained in `run` (`faults`,
    `api_key` and the errors: see `ChatServer`)."""
    judge = load_judge(run)
    return ChatServer(judge_answer(judge), host=host, port=port, faults=faults, model="gymnast-judge",
                      limits=limits, api_key=api_key, card={"judge": judge_card(judge)})


def judge_card(judge: ThresholdJudge) -> dict:
    """What `GET /v1/models` tells a client about the judge: its cameras in order, their size, the
    frame they make side by side, and the ways a request may send them."""
    config = judge.config
    size, views = config.image_size, len(config.cameras)
    return {"backend": judge.backend, "cameras": list(config.cameras), "image_size": size,
            "frame": {"width": views * size, "height": size}, "threshold": config.threshold,
            "hold_steps": config.hold_steps, "accepts": _expected(config)}


def judge_answer(judge: ThresholdJudge) -> Answer:
    """The chat server's answer function for `judge`.

    A request the judge cannot read (no ``Task:`` line, no image, images of mixed sizes, of another
    size or cameras than the judge's) raises `InvalidRequest`, so the client gets a 400 naming the
    problem rather than a reply it would read as "could not score".
    """

    def answer(request: ChatRequest) -> str:
        task = _TASK.search(request.text)
        if task is None:
            raise InvalidRequest("the messages need a line 'Task: <instruction>' (see gymnast.reward.chat.vlm.RUBRIC)",
                                 "messages", "missing_task")
        video = torch.from_numpy(judge_frames(request.frames, request.cameras, judge.config))[None]  # (1, T, S, V*S, 3)
        probability = judge.probability(video, [task.group(1).strip()]).item()
        return f"P(success) = {probability:.3f}\nANSWER: {int(probability >= judge.config.threshold)}"

    return answer


def judge_frames(frames: list[np.ndarray], cameras: list[str | None], config: JudgeConfig) -> np.ndarray:
    """(T, S, V*S, 3) the video a judge of `config` scores, from a request's images (each (H, W, 3))
    and the cameras they were named under (`ChatRequest.cameras`).

    Raises:
        InvalidRequest: no image, images of mixed sizes, of a size the judge cannot read, or per
            camera in a number or under names that do not make whole instants of its cameras.
    """
    if not frames:
        raise InvalidRequest("the messages need at least one image_url part: the video's frames", "messages",
                             "missing_image")
    shapes = [frame.shape[:2] for frame in frames]
    if len(set(shapes)) > 1:
        odd = next(i for i, shape in enumerate(shapes) if shape != shapes[0])
        raise InvalidRequest(f"the images must all have one size: image 0 is {_size(shapes[0])} but image {odd} "
                             f"is {_size(shapes[odd])}", "messages", "mixed_image_sizes")
    size, views = config.image_size, len(config.cameras)
    if views > 1 and shapes[0] == (size, views * size):  # each instant's views already side by side
        return np.stack(frames)
    if shapes[0] != (size, size):
        raise InvalidRequest(f"{_expected(config)}; got {_size(shapes[0])}: resize the frames before sending them",
                             "messages", "wrong_image_size")
    if views == 1:  # one camera, whatever its name
        return np.stack(frames)
    by_camera = _per_camera(frames, cameras, config)
    return np.stack([np.concatenate(instant, axis=1) for instant in zip(*by_camera)])  # (T, S, V*S, 3)


def _per_camera(frames: list[np.ndarray], cameras: list[str | None], config: JudgeConfig) -> list[list[np.ndarray]]:
    """Each of the judge's cameras' images in time order, from images sent one per camera."""
    names, views = config.cameras, len(config.cameras)
    if all(camera is None for camera in cameras):  # in the judge's order, one instant after another
        if len(frames) % views:
            raise InvalidRequest(f"{len(frames)} images of one camera each do not make whole instants of this judge's "
                                 f"{views} cameras: send {', '.join(names)} for each instant, in that order (or name "
                                 "each camera's images after a text line 'Camera: NAME')", "messages", "wrong_image_count")
        return [frames[v::views] for v in range(views)]
    if None in cameras:
        unnamed, named = cameras.index(None), next(i for i, camera in enumerate(cameras) if camera is not None)
        raise InvalidRequest(f"image {unnamed} follows no 'Camera: NAME' line but image {named} is named "
                             f"{cameras[named]!r}: name every image's camera or none", "messages", "unnamed_camera")
    unknown = sorted(set(cameras) - set(names))
    if unknown:
        raise InvalidRequest(f"this judge sees the cameras {', '.join(names)}, not {', '.join(unknown)}", "messages",
                             "unknown_camera")
    by_camera = [[frame for frame, camera in zip(frames, cameras) if camera == name] for name in names]
    counts = {name: len(images) for name, images in zip(names, by_camera)}
    if len(set(counts.values())) > 1:
        raise InvalidRequest("every camera needs one image per instant, but the request has "
                             + ", ".join(f"{count} of {name}" for name, count in counts.items()), "messages",
                             "wrong_image_count")
    return by_camera


def _expected(config: JudgeConfig) -> str:
    """The images a judge of `config` reads, in words."""
    size, views = config.image_size, len(config.cameras)
    if views == 1:
        return f"this judge takes {size}x{size} images (width x height), one per instant"
    return (f"this judge sees {views} cameras ({', '.join(config.cameras)}) at {size} px: send each instant as one "
            f"{views * size}x{size} image (width x height) of the views side by side in that order, or as {views} "
            f"images of {size}x{size}, one per camera, in that order or each camera's after a text line "
            "'Camera: NAME'")


def _size(shape: tuple[int, ...]) -> str:
    """'WxH' of an (H, W) shape."""
    return f"{shape[1]}x{shape[0]}"
