"""serve-judge serves every judge gymnast trains: the views side by side or one image per camera,
what `GET /v1/models` tells a client, every committed judge under results/judge, and the API key."""

import base64
import http.client
import io
import json
import socket
import time
import urllib.parse
from pathlib import Path

import numpy as np
import openai
import pytest
import torch
from PIL import Image

from gymnast.cli import main
from gymnast.policy.text import InstructionEncoder
from gymnast.reward.chat.serve import judge_answer, judge_card, judge_server
from gymnast.reward.chat.server import ChatLimits, ChatServer
from gymnast.reward.chat.vlm import VLMJudge, VLMJudgeConfig
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.train import JUDGES, load_judge

RESULTS = Path(__file__).resolve().parents[2] / "results" / "judge"
LIMITS = ChatLimits(read_timeout_s=0.5)
SIZE = 32
TASK = "Task: open the drawer"


def png_url(pixels: np.ndarray) -> str:
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")  # lossless: the server sees these very pixels
    return f"data:image/png;base64,{base64.b64encode(buffer.getvalue()).decode()}"


def request(*parts: np.ndarray | str) -> dict:
    """One user message: the Task line, then images (arrays) and text parts (strings) in order."""
    content = [{"type": "text", "text": TASK}] + [
        {"type": "text", "text": part} if isinstance(part, str) else {"type": "image_url", "image_url": {"url": png_url(part)}}
        for part in parts]
    return {"model": "gymnast-judge", "messages": [{"role": "user", "content": content}]}


def probability_said(reply) -> float:
    return float(reply.choices[0].message.content.splitlines()[0].removeprefix("P(success) = "))


def views_of(video: np.ndarray, count: int) -> list[np.ndarray]:
    """(T, S, V*S, 3) -> V arrays (T, S, S, 3), one per camera."""
    return np.split(video, count, axis=2)


@pytest.fixture(scope="module", params=[1, 2, 3], ids=lambda v: f"{v} camera(s)")
def served(request):
    """A judge of 1, 2 or 3 cameras behind a server, a client, and a video it scores (T, S, V*S, 3)."""
    torch.manual_seed(0)
    cameras = ("front", "gripper", "hand")[:request.param]
    judge = FrameJudge(JudgeConfig(width=32, image_size=SIZE, cameras=cameras)).eval()
    video = np.random.default_rng(0).integers(0, 256, (4, SIZE, len(cameras) * SIZE, 3), dtype=np.uint8)
    InstructionEncoder()(["open the drawer"])
    with ChatServer(judge_answer(judge), limits=LIMITS, card={"judge": judge_card(judge)}) as server:
        client = openai.OpenAI(base_url=server.url, api_key="EMPTY", max_retries=0, timeout=10.0)
        yield judge, client, video


def test_a_request_may_send_the_views_side_by_side_or_one_image_per_camera_in_order_or_named(served):
    judge, client, video = served
    names = judge.config.cameras
    expected = judge.probability(torch.from_numpy(video)[None], ["open the drawer"]).item()
    views = views_of(video, len(names))
    in_order = [view[t] for t in range(len(video)) for view in views]  # each instant's cameras in turn
    by_name = [part for name, view in reversed(list(zip(names, views))) for part in (f"Camera: {name}", *view)]
    per_instant = [part for t in range(len(video)) for name, view in zip(names, views)
                   for part in (f"Camera: {name}", view[t])]
    for parts in (list(video), in_order, by_name, per_instant):
        said = probability_said(client.chat.completions.create(**request(*parts)))
        assert said == pytest.approx(expected, abs=1e-3)


def test_models_says_which_cameras_size_and_order_the_judge_expects(served):
    judge, client, _ = served
    card = client.models.list().data[0].model_extra["judge"]
    views = len(judge.config.cameras)
    assert card["cameras"] == list(judge.config.cameras) and card["image_size"] == SIZE
    assert card["frame"] == {"width": views * SIZE, "height": SIZE}
    assert f"{SIZE}x{SIZE}" in card["accepts"]


def rejected(client, body: dict) -> openai.APIStatusError:
    with pytest.raises(openai.APIStatusError) as raised:
        client.chat.completions.create(**body)
    return raised.value


def test_images_that_make_no_whole_instant_of_the_judges_cameras_get_a_400_naming_the_fault(served):
    judge, client, video = served
    names = judge.config.cameras
    views = views_of(video, len(names))
    if len(names) == 1:  # every square image is a whole instant, named or not
        assert client.chat.completions.create(**request("Camera: wrist", *views[0][:3])).choices
        return
    cases = {
        "wrong_image_count": request(*[views[0][t] for t in range(len(names) + 1)]),
        "unknown_camera": request("Camera: top", *views[0]),
        "unnamed_camera": request(views[0][0], "Camera: front", views[0][1]),
    }
    uneven = request(*[part for name, view in zip(names, views) for part in (f"Camera: {name}", *view)][:-1])
    cases["wrong_image_count (uneven)"] = uneven
    for code, body in cases.items():
        error = rejected(client, body)
        assert error.status_code == 400 and error.code == code.split()[0], (code, error.body)
    assert "of front" in rejected(client, uneven).body["message"]


def committed_judges() -> list[Path]:
    """Every judge run under results/judge whose weights are committed (checkpoints of a run aside)."""
    backends = {judge.backend for judge in JUDGES.values()}
    runs = []
    for config in sorted(RESULTS.rglob("config.json")):
        run = config.parent
        weights = (run / "model.safetensors").is_file() or (run / "checkpoints" / "last").is_file()
        if "checkpoints" not in run.parts and weights and json.loads(config.read_text())["model"]["backend"] in backends:
            runs.append(run)
    return runs


def test_the_committed_judges_are_found():
    runs = committed_judges()
    assert RESULTS / "judge" in runs and len(runs) >= 10
    cameras = {len(load_judge(run).config.cameras) for run in runs}
    assert cameras == {1, 2, 3}


@pytest.mark.parametrize("run", committed_judges(), ids=lambda run: str(run.relative_to(RESULTS)))
def test_every_committed_judge_answers_a_valid_request_and_names_each_fault(run):
    with judge_server(run, limits=LIMITS) as server:
        judge = load_judge(run)
        names, size = judge.config.cameras, judge.config.image_size
        video = np.random.default_rng(0).integers(0, 256, (3, size, len(names) * size, 3), dtype=np.uint8)
        client = openai.OpenAI(base_url=server.url, api_key="EMPTY", max_retries=0, timeout=30.0)
        card = client.models.list().data[0].model_extra["judge"]
        assert card["cameras"] == list(names) and card["frame"] == {"width": len(names) * size, "height": size}
        square = views_of(video, len(names))
        for parts in (list(video), [view[t] for t in range(len(video)) for view in square]):
            reply = client.chat.completions.create(**request(*parts))
            assert reply.choices[0].message.content.splitlines()[-1] in ("ANSWER: 0", "ANSWER: 1")
        half = video[:, : size // 2]
        faults = {  # code: (request, words the message must hold)
            "wrong_image_size": (request(*half), f"got {len(names) * size}x{size // 2}"),
            "mixed_image_sizes": (request(video[0], half[0]), "must all have one size"),
            "missing_image": (request(), "at least one image_url"),
            "missing_task": ({"model": "m", "messages": [{"role": "user", "content": [
                {"type": "image_url", "image_url": {"url": png_url(video[0])}}]}]}, "Task: <instruction>"),
        }
        if len(names) > 1:
            faults["wrong_image_count"] = (request(*square[0][:1]), f"{len(names)} cameras")
            faults["unknown_camera"] = (request("Camera: top", *[view[0] for view in square]), "not top")
        for code, (body, says) in faults.items():
            error = rejected(client, body)
            assert 400 <= error.status_code < 500 and error.code == code and says in error.body["message"], error.body


# --- The API key -------------------------------------------------------------------------------------

KEY = "sk-gymnast-test-key"


class Counter:
    """An answer function that counts its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, request):
        self.calls += 1
        return "ANSWER: 1"


def raw(server, head: str) -> tuple[int, dict, float]:
    """Send a request's head alone on a fresh connection (no body follows); (status, JSON, seconds)."""
    url = urllib.parse.urlsplit(server.url)
    start = time.monotonic()
    with socket.create_connection((url.hostname, url.port), timeout=10) as sock:
        sock.sendall(head.encode())
        response = http.client.HTTPResponse(sock)
        response.begin()
        return response.status, json.loads(response.read()), time.monotonic() - start


@pytest.mark.parametrize("authorization", [None, "Bearer wrong-key", "Basic c2stZ3ltbmFzdA==", f"Bearer{KEY}"])
def test_without_the_key_a_request_gets_401_from_its_headers_and_is_never_scored(authorization):
    answer = Counter()
    with ChatServer(answer, limits=LIMITS, api_key=KEY) as server:
        line = f"Authorization: {authorization}\r\n" if authorization else ""
        # A body of 60 MB is declared and never sent (Expect: 100-continue too): the 401 comes from the headers.
        status, body, seconds = raw(server, "POST /v1/chat/completions HTTP/1.1\r\nHost: x\r\nContent-Length: 60000000\r\n"
                                            f"Expect: 100-continue\r\n{line}\r\n")
        assert status == 401 and seconds < LIMITS.read_timeout_s + 0.5
        assert body["error"]["type"] == "authentication_error"
        assert body["error"]["code"] in ("missing_api_key", "invalid_api_key") and KEY not in body["error"]["message"]
        status, body, _ = raw(server, f"GET /v1/models HTTP/1.1\r\nHost: x\r\n{line}\r\n")
        assert status == 401
        client = openai.OpenAI(base_url=server.url, api_key="wrong", max_retries=0, timeout=10.0)
        with pytest.raises(openai.AuthenticationError):
            client.chat.completions.create(model="m", messages=[{"role": "user", "content": "Task: x"}])
    assert answer.calls == 0


def test_with_the_key_the_openai_client_and_the_vlm_judge_are_answered(monkeypatch):
    answer = Counter()
    with ChatServer(answer, limits=LIMITS, api_key=KEY) as server:
        client = openai.OpenAI(base_url=server.url, api_key=KEY, max_retries=0, timeout=10.0)
        assert client.chat.completions.create(model="m", messages=[{"role": "user", "content": "hi"}]).choices
        assert client.models.list().data[0].id == "gymnast-judge"
        monkeypatch.setenv("JUDGE_KEY", KEY)
        judge = VLMJudge(VLMJudgeConfig(model="m", base_url=server.url, samples=1, api_key_env="JUDGE_KEY"))
        assert judge.score(torch.zeros(1, 3, 8, 8, 3, dtype=torch.uint8), ["reach"]).tolist() == [1.0]
    assert answer.calls == 2


def test_a_server_reachable_from_other_machines_needs_a_key(capsys):
    for host in ("0.0.0.0", ""):
        with pytest.raises(ValueError, match="without an API key"):
            ChatServer(Counter(), host=host)
    with pytest.raises(ValueError, match="API key is empty"):
        ChatServer(Counter(), api_key=" ")
    ChatServer(Counter(), host="0.0.0.0", api_key=KEY).stop()  # with a key it may
    ChatServer(Counter(), host="localhost").stop()  # this machine alone needs none
    with pytest.raises(SystemExit):
        main(["serve-judge", "--judge", str(RESULTS / "one_camera" / "judge"), "--host", "0.0.0.0", "--port", "0"])
    assert "refusing to serve on 0.0.0.0 without an API key" in capsys.readouterr().err
