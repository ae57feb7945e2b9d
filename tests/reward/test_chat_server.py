"""serve-judge under bad input: every malformed, oversized or stalled request gets a 4xx JSON error in
the OpenAI shape, sent both as raw HTTP and through the real `openai` client, and the server serves on;
the whole suite runs against judges of one, two and three cameras."""

import base64
import http.client
import io
import json
import logging
import socket
import time
import urllib.parse

import numpy as np
import openai
import pytest
import torch
from PIL import Image

from gymnast.cli import main
from gymnast.policy.text import InstructionEncoder
from gymnast.reward.chat.server import ChatLimits, ChatServer
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.video import LearnedJudge
from gymnast.reward.chat.serve import judge_answer

LIMITS = ChatLimits(max_body_mb=0.5, read_timeout_s=0.5, max_choices=4)
SIZE = 32  # the tiny judge's image size


def data_url(data: bytes, kind: str = "jpeg") -> str:
    return f"data:image/{kind};base64,{base64.b64encode(data).decode()}"


def jpeg(height: int = SIZE, width: int = SIZE) -> bytes:
    pixels = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="JPEG")
    return buffer.getvalue()


def messages(*images: bytes | str, text: str = "Task: open the drawer") -> list[dict]:
    """One user message: the rubric's Task line and the images (bytes, or a ready URL)."""
    parts = [{"type": "image_url", "image_url": {"url": image if isinstance(image, str) else data_url(image)}}
             for image in images]
    return [{"role": "user", "content": [{"type": "text", "text": text}, *parts]}]


# Six images of one camera each: whole instants of a judge of one, two or three cameras.
GOOD = {"model": "gymnast-judge", "messages": messages(*[jpeg()] * 6)}
JUDGES = {  # untrained: only their answers' form matters
    "video judge, one camera": lambda: LearnedJudge(JudgeConfig(width=32, image_size=SIZE)),
    "frame judge, two cameras": lambda: FrameJudge(JudgeConfig(width=32, image_size=SIZE, cameras=("front", "gripper"))),
    "frame judge, three cameras": lambda: FrameJudge(JudgeConfig(width=32, image_size=SIZE,
                                                                 cameras=("front", "gripper", "hand"))),
}


@pytest.fixture(scope="module", params=JUDGES, ids=str)
def server(request):
    torch.manual_seed(0)
    judge = JUDGES[request.param]().eval()
    InstructionEncoder()(["load the sentence encoder"])  # before serving: its first load takes seconds
    with ChatServer(judge_answer(judge), limits=LIMITS) as running:
        yield running


@pytest.fixture(scope="module")
def client(server):
    return openai.OpenAI(base_url=server.url, api_key="EMPTY", max_retries=0, timeout=10.0)


def address(server) -> tuple[str, int]:
    url = urllib.parse.urlsplit(server.url)
    return url.hostname, url.port


def post(body: bytes | str, **headers: str) -> bytes:
    """The bytes of a chat-completions POST; `headers` override the computed Content-Length."""
    body = body.encode() if isinstance(body, str) else body
    fields = {"Host": "localhost", "Content-Type": "application/json", "Content-Length": str(len(body))} | {
        name.replace("_", "-"): value for name, value in headers.items()}
    head = "".join(f"{name}: {value}\r\n" for name, value in fields.items() if value is not None)
    return f"POST /v1/chat/completions HTTP/1.1\r\n{head}\r\n".encode() + body


def exchange(server, request: bytes) -> tuple[int, dict, float]:
    """Send raw bytes on a fresh connection; (status, JSON body, seconds until the answer was read)."""
    start = time.monotonic()
    with socket.create_connection(address(server), timeout=10) as sock:
        sock.sendall(request)
        response = http.client.HTTPResponse(sock)
        response.begin()
        body = json.loads(response.read())
    return response.status, body, time.monotonic() - start


def assert_openai_error(body: dict, code: str, param: str | None, says: str) -> None:
    error = body["error"]
    assert set(error) == {"message", "type", "param", "code"}
    assert error["type"] == "invalid_request_error" and error["code"] == code and error["param"] == param
    assert says in error["message"], error["message"]


def assert_still_serves(client) -> None:
    reply = client.chat.completions.create(**GOOD)
    assert reply.choices[0].message.content.splitlines()[-1] in ("ANSWER: 0", "ANSWER: 1")


def as_json(payload: dict) -> bytes:
    return json.dumps(payload).encode()


TRUNCATED_JPEG = jpeg()[:300]
HUGE_CANVAS = io.BytesIO()
Image.new("1", (5000, 4000)).save(HUGE_CANVAS, format="PNG")  # small file, 20 megapixels

# (status, code, param, words the message must contain, the raw request)
MALFORMED = {
    "not json": (400, "invalid_json", None, "not valid JSON", post("{not json")),
    "not utf-8": (400, "invalid_json", None, "not valid JSON", post(b"\xff\xfe\x00{")),
    "empty body": (400, "invalid_json", None, "body is empty", post("")),
    "a json array": (400, "invalid_type", None, "must be a JSON object, got a JSON array", post("[1, 2]")),
    "no messages": (400, "missing_field", "messages", "'messages' is required", post('{"model": "m"}')),
    "messages a string": (400, "invalid_type", "messages", "got a JSON string",
                          post('{"model": "m", "messages": "hello"}')),
    "messages empty": (400, "invalid_type", "messages", "got an empty list", post('{"messages": []}')),
    "a message not an object": (400, "invalid_type", "messages[0]", "must be an object",
                                post('{"messages": ["hi"]}')),
    "no role": (400, "missing_field", "messages[0].role", "is required", post('{"messages": [{"content": "hi"}]}')),
    "content a number": (400, "invalid_type", "messages[0].content", "got a JSON number",
                         post('{"messages": [{"role": "user", "content": 3}]}')),
    "unknown part type": (400, "invalid_value", "messages[0].content[0].type", "got 'audio'",
                          post('{"messages": [{"role": "user", "content": [{"type": "audio"}]}]}')),
    "text not a string": (400, "invalid_type", "messages[0].content[0].text", "must be a string",
                          post('{"messages": [{"role": "user", "content": [{"type": "text", "text": 1}]}]}')),
    "image_url a string": (400, "invalid_type", "messages[0].content[1].image_url", "must be an object",
                           post(as_json({"messages": [{"role": "user", "content": [
                               {"type": "text", "text": "Task: x"}, {"type": "image_url", "image_url": "x"}]}]}))),
    "model a number": (400, "invalid_type", "model", "must be a string", post(as_json({**GOOD, "model": 5}))),
    "web address": (400, "invalid_image", "messages[0].content[1].image_url.url", "fetches no web addresses",
                    post(as_json({"messages": messages("https://example.com/frame.jpg")}))),
    "not base64": (400, "invalid_image", "messages[0].content[1].image_url.url", "not valid base64",
                   post(as_json({"messages": messages("data:image/jpeg;base64,@@not base64@@")}))),
    "base64 not an image": (400, "invalid_image", "messages[0].content[2].image_url.url", "do not decode as an image",
                            post(as_json({"messages": messages(jpeg(), b"just some text, not a picture")}))),
    "truncated jpeg": (400, "invalid_image", "messages[0].content[1].image_url.url", "do not decode as an image",
                       post(as_json({"messages": messages(TRUNCATED_JPEG)}))),
    "huge canvas": (400, "image_too_large", "messages[0].content[1].image_url.url", "5000x4000 pixels",
                    post(as_json({"messages": messages(data_url(HUGE_CANVAS.getvalue(), "png"))}))),
    "mixed image sizes": (400, "mixed_image_sizes", "messages", "image 0 is 32x32 but image 1 is 48x32",
                          post(as_json({"messages": messages(jpeg(), jpeg(SIZE, 48))}))),
    "not the judge's size": (400, "wrong_image_size", "messages", "got 64x64: resize the frames",
                             post(as_json({"messages": messages(jpeg(64, 64))}))),
    "no task line": (400, "missing_task", "messages", "'Task: <instruction>'",
                     post(as_json({"messages": messages(jpeg(), text="is it done?")}))),
    "no image": (400, "missing_image", "messages", "at least one image_url", post(as_json({"messages": messages()}))),
    "n = -1": (400, "invalid_value", "n", "from 1 to 4 (the server's --max-choices), got -1",
               post(as_json({**GOOD, "n": -1}))),
    "n = 0": (400, "invalid_value", "n", "got 0", post(as_json({**GOOD, "n": 0}))),
    "n = 1.5": (400, "invalid_value", "n", "got 1.5", post(as_json({**GOOD, "n": 1.5}))),
    "n a string": (400, "invalid_value", "n", 'got "2"', post(as_json({**GOOD, "n": "2"}))),
    "n past the limit": (400, "invalid_value", "n", "got 5", post(as_json({**GOOD, "n": 5}))),
    "content-length abc": (400, "invalid_content_length", None, "got 'abc'",
                           post(as_json(GOOD), Content_Length="abc")),
    "two content-lengths": (400, "invalid_content_length", None, "one byte count",
                            post("{}", Content_Length="2\r\nContent-Length: 3")),
    "no content-length": (411, "length_required", None, "Content-Length header is required",
                          post("", Content_Length=None)),
    "chunked body": (411, "length_required", None, "chunked request bodies are not supported",
                     post(b"2\r\n{}\r\n0\r\n\r\n", Content_Length=None, Transfer_Encoding="chunked")),
    "body over the limit": (413, "body_too_large", None, "60.0 MB, over this server's limit of 0.5 MB (--max-body-mb)",
                            post(b"", Content_Length="60000000")),  # declared, never sent
    "body shorter than declared": (408, "incomplete_body", None, "ended after 2 of the 100 bytes",
                                   post(b"{}", Content_Length="100")),
    "headers that stall": (408, "request_timeout", None, "did not arrive within 0.5 s",
                           b"POST /v1/chat/completions HTTP/1.1\r\nHost: localhost\r\n"),
    "bad request line": (400, "bad_http", None, "Bad request syntax", b"NONSENSE\r\n\r\n"),
    "unsupported method": (405, "bad_http", None, "method PUT is not supported",
                           b"PUT /v1/chat/completions HTTP/1.1\r\nHost: localhost\r\nContent-Length: 0\r\n\r\n"),
}


@pytest.mark.parametrize("case", MALFORMED, ids=str)
def test_each_malformed_raw_request_gets_a_4xx_openai_error_and_the_server_serves_on(server, client, caplog, case):
    status, code, param, says, request = MALFORMED[case]
    with caplog.at_level(logging.WARNING, logger="gymnast.reward.chat.server"):
        answered, body, seconds = exchange(server, request)
    assert answered == status
    assert_openai_error(body, code, param, says)
    assert seconds < LIMITS.read_timeout_s + 2.0  # answered within the read timeout, never left hanging
    assert any(f"-> {status} " in record.getMessage() for record in caplog.records)
    assert_still_serves(client)


# What the openai client can express: (status, code, param, words in the message, create() arguments)
THROUGH_THE_CLIENT = {
    "messages a string": (400, "invalid_type", "messages", "got a JSON string", {"messages": "hello"}),
    "no role": (400, "missing_field", "messages[0].role", "is required", {"messages": [{"content": "hi"}]}),
    "base64 not an image": (400, "invalid_image", "messages[0].content[1].image_url.url", "do not decode",
                            {"messages": messages(b"\x00" * 64)}),
    "truncated jpeg": (400, "invalid_image", "messages[0].content[1].image_url.url", "do not decode",
                       {"messages": messages(TRUNCATED_JPEG)}),
    "mixed image sizes": (400, "mixed_image_sizes", "messages", "image 1 is 32x48",
                          {"messages": messages(jpeg(), jpeg(48, SIZE))}),
    "n = -1": (400, "invalid_value", "n", "got -1", {"messages": GOOD["messages"], "n": -1}),
    "n = 0": (400, "invalid_value", "n", "got 0", {"messages": GOOD["messages"], "n": 0}),
    "body over the limit": (413, "body_too_large", None, "over this server's limit of 0.5 MB",
                            {"messages": messages(b"\x00" * 600_000)}),  # sent in full: the 413 must still arrive
}


@pytest.mark.parametrize("case", THROUGH_THE_CLIENT, ids=str)
def test_the_openai_client_gets_each_error_it_can_send_and_the_server_serves_on(client, case):
    status, code, param, says, arguments = THROUGH_THE_CLIENT[case]
    with pytest.raises(openai.APIStatusError) as raised:
        client.chat.completions.create(model="gymnast-judge", **arguments)
    error = raised.value
    assert error.status_code == status and error.code == code and error.param == param
    assert error.type == "invalid_request_error" and says in error.body["message"]
    assert_still_serves(client)


def test_a_bad_json_request_keeps_its_connection_usable(server):
    connection = http.client.HTTPConnection(*address(server), timeout=10)
    try:
        connection.request("POST", "/v1/chat/completions", body=b"{not json")
        first = connection.getresponse()
        assert first.status == 400 and json.loads(first.read())["error"]["code"] == "invalid_json"
        connection.request("POST", "/v1/chat/completions", body=as_json({**GOOD, "n": 2}))
        second = connection.getresponse()
        assert second.status == 200 and len(json.loads(second.read())["choices"]) == 2
    finally:
        connection.close()


def test_an_idle_kept_alive_connection_is_not_timed_out_as_a_stalled_request(server):
    connection = http.client.HTTPConnection(*address(server), timeout=10)
    try:
        connection.request("GET", "/v1/models")
        assert connection.getresponse().read()
        time.sleep(LIMITS.read_timeout_s * 2)
        connection.request("GET", "/v1/models")
        assert connection.getresponse().status == 200
    finally:
        connection.close()


def test_a_failing_answer_function_is_a_500_in_the_openai_shape_and_the_server_serves_on():
    calls = []

    def answer(request):
        calls.append(request.text)
        if len(calls) == 1:
            raise RuntimeError("the model fell over")
        return "ANSWER: 1"

    with ChatServer(answer, limits=LIMITS) as server:
        client = openai.OpenAI(base_url=server.url, api_key="EMPTY", max_retries=0, timeout=10.0)
        with pytest.raises(openai.InternalServerError) as raised:
            client.chat.completions.create(model="m", messages=[{"role": "user", "content": "hi"}])
        assert raised.value.type == "server_error" and "the model fell over" in raised.value.body["message"]
        assert client.chat.completions.create(model="m", messages=[{"role": "user", "content": "hi"}]).choices


def test_serve_judge_takes_its_limits_from_the_command_line(capsys):
    with pytest.raises(SystemExit):
        main(["serve-judge", "--help"])
    help_text = capsys.readouterr().out
    assert all(flag in help_text for flag in ("--max-body-mb", "--read-timeout-s", "--max-choices"))
    with pytest.raises(SystemExit):
        main(["serve-judge", "--judge", "nowhere", "--read-timeout-s", "0"])
    assert "limits must be positive" in capsys.readouterr().err
