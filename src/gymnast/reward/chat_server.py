"""A small HTTP server speaking the OpenAI chat-completions protocol, standard library only.

It puts any `answer(text, frames) -> str` function behind `POST /v1/chat/completions`, so that the
VLM judge can be tested with the real `openai` client over real HTTP, and so that a local judge can
be served to anything that speaks the protocol. `faults` injects the failures a real deployment
shows (rate limits, server errors, slow or malformed answers), one per request, in order.
"""

from __future__ import annotations

import base64
import collections
import io
import json
import logging
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
from PIL import Image

logger = logging.getLogger(__name__)

Answer = Callable[[str, list[np.ndarray]], str]


def decode_image(url: str) -> np.ndarray:
    """(H, W, 3) uint8 pixels of a `data:image/...;base64,...` URL."""
    header, _, payload = url.partition(",")
    if not header.startswith("data:image/") or not header.endswith(";base64"):
        raise ValueError(f"only base64 image data URLs are supported, got {url[:40]!r}")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(payload))).convert("RGB"))


def read_messages(messages: list[dict]) -> tuple[str, list[np.ndarray]]:
    """The text parts of all messages joined by newlines, and their images in order."""
    texts, frames = [], []
    for message in messages:
        content = message.get("content")
        parts = [{"type": "text", "text": content}] if isinstance(content, str) else content or []
        for part in parts:
            if part.get("type") == "text":
                texts.append(part["text"])
            elif part.get("type") == "image_url":
                frames.append(decode_image(part["image_url"]["url"]))
    return "\n".join(texts), frames


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.1"  # keep-alive, as the openai client expects

    def log_message(self, format: str, *args: object) -> None:
        logger.debug("%s %s", self.address_string(), format % args)

    def _send(self, status: int, body: bytes, headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        for name, value in (headers or {}).items():
            self.send_header(name, value)
        self.end_headers()
        self.wfile.write(body)

    def _json(self, status: int, payload: dict, headers: dict[str, str] | None = None) -> None:
        self._send(status, json.dumps(payload).encode(), headers)

    def _error(self, status: int, message: str, kind: str, headers: dict[str, str] | None = None) -> None:
        self._json(status, {"error": {"message": message, "type": kind, "code": status}}, headers)

    def do_GET(self) -> None:
        if self.path.rstrip("/") != "/v1/models":
            return self._error(404, f"no route GET {self.path}", "not_found_error")
        model = {"id": self.server.chat.model, "object": "model", "created": 0, "owned_by": "gymnast"}
        self._json(200, {"object": "list", "data": [model]})

    def do_POST(self) -> None:
        # Read the body first, whatever the path, so that the connection stays usable.
        body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
        if self.path.rstrip("/") != "/v1/chat/completions":
            return self._error(404, f"no route POST {self.path}", "not_found_error")
        chat = self.server.chat
        fault = chat.next_fault()
        if fault == "429":
            return self._error(429, "rate limited (injected fault)", "rate_limit_error", {"Retry-After": "0"})
        if fault == "500":
            return self._error(500, "server error (injected fault)", "server_error")
        if fault == "invalid_json":
            return self._send(200, b"{this is not json")
        if fault.startswith("slow:"):
            time.sleep(float(fault.removeprefix("slow:")))
        try:
            request = json.loads(body)
            text, frames = read_messages(request["messages"])
            n = int(request.get("n") or 1)
        except (ValueError, KeyError, TypeError, AttributeError) as error:
            return self._error(400, f"invalid request: {error}", "invalid_request_error")
        contents = ["the robot looks nice" if fault == "garbage" else chat.answer(text, frames) for _ in range(n)]
        prompt_tokens = len(text) // 4 + 85 * len(frames)  # rough: ~4 characters a token, 85 a small image
        completion_tokens = sum(len(content) // 4 + 1 for content in contents)
        self._json(200, {
            "id": f"chatcmpl-{uuid.uuid4().hex}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": request.get("model") or chat.model,
            "choices": [{"index": i, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}
                        for i, content in enumerate(contents)],
            "usage": {"prompt_tokens": prompt_tokens, "completion_tokens": completion_tokens,
                      "total_tokens": prompt_tokens + completion_tokens},
        })


class _Server(ThreadingHTTPServer):
    daemon_threads = True  # a slow request must not keep the process (or stop()) waiting
    chat: ChatServer

    def handle_error(self, request: object, client_address: object) -> None:
        # Clients that time out and hang up are expected (the timeout tests); do not spray tracebacks.
        logger.debug("chat server: error while serving %s", client_address, exc_info=True)


class ChatServer:
    """An OpenAI-compatible chat-completions server around an answer function.

    Args:
        answer: `answer(text, frames)` gets a request's text (all text parts joined) and its images,
            each (H, W, 3) uint8, and returns the assistant's reply; called once per choice (`n`),
            from the server's threads, so it must be thread-safe.
        host: interface to listen on.
        port: port to listen on; 0 picks a free one (see `url`).
        faults: failures to inject, consumed one per chat request in order: "429", "500",
            "slow:SECONDS" (delay, then answer), "garbage" (a reply with no ANSWER line),
            "invalid_json" (a 200 whose body is not JSON).
        model: the model name that `GET /v1/models` lists.

    Attributes:
        requests_served: chat-completion requests received so far, faulted ones included.
    """

    def __init__(self, answer: Answer, host: str = "127.0.0.1", port: int = 0, faults: Sequence[str] = (),
                 model: str = "gymnast-judge") -> None:
        self.answer, self.host, self.model = answer, host, model
        self.faults = collections.deque(faults)
        self.requests_served = 0
        self._lock = threading.Lock()
        self._httpd = _Server((host, port), _Handler)
        self._httpd.chat = self
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """API root for clients, `http://host:port/v1`."""
        return f"http://{self.host}:{self._httpd.server_address[1]}/v1"

    def next_fault(self) -> str:
        """Count a chat request and return its fault ("" when none is queued)."""
        with self._lock:
            self.requests_served += 1
            return self.faults.popleft() if self.faults else ""

    def start(self) -> ChatServer:
        """Serve from a daemon thread; returns self."""
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="chat-server", daemon=True)  # poll often: stop() waits a poll
        self._thread.start()
        logger.info("chat server listening at %s", self.url)
        return self

    def stop(self) -> None:
        """Stop serving and close the socket."""
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join()
            self._thread = None
        self._httpd.server_close()

    def __enter__(self) -> ChatServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
