"""The VLM judge, with the real `openai` client against a real local chat-completions server."""

import itertools
import json
import math
import re
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
import torch

from gymnast.reward.chat.server import ChatServer
from gymnast.reward.chat.vlm import VLMJudge, VLMJudgeConfig, parse_answer

INSTRUCTIONS = ["open the drawer", "close it"]


def task(text):
    return re.search(r"Task: (.*)", text).group(1)


class Recorder:
    """Answers 1 for tasks that say "open", 0 otherwise, and keeps the frames of every call."""

    def __init__(self):
        self.calls = []
        self.lock = threading.Lock()

    def __call__(self, request):
        with self.lock:
            self.calls.append((task(request.text), request.frames))
        return "The drawer moved.\nANSWER: 1" if "open" in task(request.text) else "Nothing happened.\nANSWER: 0"


def videos(batch=2, steps=7, seed=0):
    generator = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (batch, steps, 32, 32, 3), generator=generator, dtype=torch.uint8)


def judge_for(server, **overrides):
    settings = {"model": "judge", "base_url": server.url, "samples": 1, "backoff_s": 0.01, "timeout_s": 5.0}
    return VLMJudge(VLMJudgeConfig(**(settings | overrides)))


@pytest.fixture
def recorder():
    return Recorder()


def test_scores_follow_the_judges_answers_and_it_sees_every_third_frame_and_the_last(recorder):
    frames = videos()
    with ChatServer(recorder) as server:
        scores = judge_for(server).score(frames, INSTRUCTIONS)
    assert scores.dtype == torch.float32
    assert scores.tolist() == [1.0, 0.0]
    for instruction, images in recorder.calls:
        assert len(images) == 3 and all(image.shape == (32, 32, 3) for image in images)
        # JPEG changes noise a little, random frames a lot: each image is nearest to the frame it was.
        video = frames[INSTRUCTIONS.index(instruction)].numpy().astype(float)  # (T, H, W, 3)
        nearest = [int(np.abs(video - image.astype(float)).mean(axis=(1, 2, 3)).argmin()) for image in images]
        assert nearest == [0, 3, 6]


def test_each_sample_is_one_request(recorder):
    with ChatServer(recorder) as server:
        judge = judge_for(server, samples=3)
        judge.score(videos(), INSTRUCTIONS)
    assert server.requests_served == 6 and len(recorder.calls) == 6
    assert judge.metrics()["reward/vlm_requests"] == 6.0
    assert judge.metrics()["reward/vlm_prompt_tokens"] > 0 and judge.metrics()["reward/vlm_completion_tokens"] > 0


@pytest.mark.parametrize(("answers", "expected"), [("110", 1.0), ("001", 0.0), ("10", 0.5)])
def test_the_samples_are_majority_voted(answers, expected):
    cycle, lock = itertools.cycle(answers), threading.Lock()

    def answer(request):
        with lock:
            return f"ANSWER: {next(cycle)}"

    with ChatServer(answer) as server:
        scores = judge_for(server, samples=len(answers)).score(videos(batch=1), ["open the drawer"])
    assert scores.tolist() == [expected]


def test_an_identical_video_is_never_paid_for_twice(recorder):
    frames = videos()
    with ChatServer(recorder) as server:
        judge = judge_for(server, samples=2)
        first = judge.score(frames, INSTRUCTIONS)
        second = judge.score(frames, INSTRUCTIONS)
        duplicated = judge.score(torch.cat([frames[:1], frames[:1]]), INSTRUCTIONS[:1] * 2)
    assert torch.equal(first, second) and duplicated.tolist() == [1.0, 1.0]
    assert server.requests_served == 4
    assert judge.stats["cache_hits"] == 4


def test_rate_limits_and_server_errors_are_retried_and_counted(recorder):
    with ChatServer(recorder, faults=["429", "500"]) as server:
        judge = judge_for(server)
        scores = judge.score(videos(batch=1), ["open the drawer"])
    assert scores.tolist() == [1.0]
    assert judge.stats["retries"] == 2 and judge.stats["requests"] == 3 and judge.stats["failures"] == 0


def test_a_sample_that_keeps_failing_becomes_nan_without_raising(recorder):
    with ChatServer(recorder, faults=["500", "429", "500"]) as server:
        judge = judge_for(server, max_retries=2)
        scores = judge.score(videos(batch=1), ["open the drawer"])
    assert math.isnan(scores.item())
    assert judge.stats["failures"] == 1 and judge.stats["retries"] == 2
    # Nothing cached: the next call asks again, and now the server answers.
    with ChatServer(recorder) as server:
        assert judge_for(server).score(videos(batch=1), ["open the drawer"]).tolist() == [1.0]


@pytest.mark.parametrize("fault", ["garbage", "invalid_json"])
def test_a_malformed_answer_is_nan_and_counted(recorder, fault):
    with ChatServer(recorder, faults=[fault]) as server:
        judge = judge_for(server)
        scores = judge.score(videos(batch=1), ["open the drawer"])
    assert math.isnan(scores.item())
    assert judge.stats["malformed"] == 1 and judge.stats["failures"] == 0


def test_a_malformed_sample_is_left_out_of_the_vote(recorder):
    with ChatServer(recorder, faults=["garbage"]) as server:
        judge = judge_for(server, samples=3, concurrency=1)
        assert judge.score(videos(batch=1), ["open the drawer"]).tolist() == [1.0]
    assert judge.stats["malformed"] == 1


def test_a_hanging_server_times_out_to_nan_quickly(recorder):
    with ChatServer(recorder, faults=["slow:2", "slow:2"]) as server:
        judge = judge_for(server, timeout_s=0.5, max_retries=1)
        start = time.monotonic()
        scores = judge.score(videos(batch=1), ["open the drawer"])
        elapsed = time.monotonic() - start
    assert math.isnan(scores.item()) and judge.stats["failures"] == 1
    assert elapsed < 5  # a hang guard, not a benchmark


def test_a_configuration_error_is_raised_naming_the_endpoint(recorder):
    with ChatServer(recorder) as server:
        judge = VLMJudge(VLMJudgeConfig(model="judge", base_url=server.url.removesuffix("/v1") + "/nowhere"))
        with pytest.raises(RuntimeError, match=r"/nowhere.*model judge"):
            judge.score(videos(batch=1), ["open the drawer"])


@pytest.mark.parametrize(
    ("text", "expected"),
    [("ANSWER: 1", 1.0), ("answer:0", 0.0), ("It worked.\nAnswer:  1", 1.0), ("ANSWER: 1\nANSWER: 0", 0.0),
     ("final: yes", math.nan), ("", math.nan), ("ANSWER: maybe", math.nan)],
)
def test_parse_answer_reads_the_last_answer_line(text, expected):
    result = parse_answer(text)
    assert result == expected or (math.isnan(expected) and math.isnan(result))


def test_the_api_key_comes_from_the_named_environment_variable_and_is_never_shown(monkeypatch, recorder):
    monkeypatch.setenv("GYMNAST_TEST_JUDGE_KEY", "sk-secret-123")
    with ChatServer(recorder) as server:
        judge = judge_for(server, api_key_env="GYMNAST_TEST_JUDGE_KEY")
        judge.score(videos(batch=1), ["open the drawer"])
    assert judge.client.api_key == "sk-secret-123"
    assert "sk-secret-123" not in repr(judge) and "sk-secret-123" not in repr(judge.config)
    assert "sk-secret-123" not in json.dumps(judge.metrics())
    monkeypatch.delenv("GYMNAST_TEST_JUDGE_KEY")
    assert judge_for(server, api_key_env="GYMNAST_TEST_JUDGE_KEY").client.api_key == "EMPTY"


def test_the_server_lists_its_model_and_rejects_bad_requests(recorder):
    with ChatServer(recorder, model="judge-1") as server:
        with urllib.request.urlopen(server.url + "/models") as response:
            assert [model["id"] for model in json.load(response)["data"]] == ["judge-1"]
        bad = urllib.request.Request(server.url + "/chat/completions", data=b"{not json", method="POST")
        with pytest.raises(urllib.error.HTTPError) as error:
            urllib.request.urlopen(bad)
        assert error.value.code == 400 and json.load(error.value)["error"]["type"] == "invalid_request_error"
        with pytest.raises(urllib.error.HTTPError) as error:
            urllib.request.urlopen(server.url + "/elsewhere")
        assert error.value.code == 404
