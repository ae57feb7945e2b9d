"""A small HTTP server speaking the OpenAI chat-completions protocol, standard library only.

It puts any `answer(text, frames) -> str` function behind `POST /v1/chat/completions`, so that the
VLM judge can be tested with the real `openai` client over real HTTP, and so that a local judge can
be served to anything that speaks the protocol. `faults` injects the failures a real deployment
shows (rate limits, server errors, slow or malformed answers), one per request, in order.

Every request gets an answer: a malformed one (see `gymnast.reward.chat.request`), one past the
`ChatLimits`, or one that stalls gets a 4xx JSON error in the OpenAI shape
(``{"error": {"message", "type", "param", "code"}}``), is logged, and the server serves on.

With an API key, every request must carry it as the OpenAI clients send theirs (``Authorization:
Bearer KEY``); one without it is answered 401 from its headers, before its body is read. A server
without a key listens on this machine only: anyone who can reach a wider address could otherwise
spend its compute and read its model's answers.
"""

from __future__ import annotations

import collections
import dataclasses
import hmac
import ipaddress
import json
import logging
import re
import socket
import threading
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from gymnast.reward.chat.request import ChatRequest, InvalidRequest, parse_chat_request

logger = logging.getLogger(__name__)

Answer = Callable[[ChatRequest], str]

# How long a kept-alive connection may wait for its next request. Longer than the keep-alive expiry
# of common clients (httpx: 5 s), so that a client never reuses a connection the server is closing.
IDLE_TIMEOUT_S = 60.0
_MB = 1_000_000
_BYTE_COUNT = re.compile(r"\s*[0-9]+\s*")  # a usable Content-Length value


@dataclasses.dataclass(frozen=True)
class ChatLimits:
    """What the chat server accepts; a request past a limit gets a 4xx JSON error that names it."""

    max_body_mb: float = 16.0
    """Largest request body, in MB (10^6 bytes); a longer one is answered 413 as soon as its
    Content-Length shows it, and never stored."""
    read_timeout_s: float = 5.0
    """Seconds a request may take to arrive once it has begun (a stalled request, or a body shorter
    than its Content-Length, is answered 408 when they are up)."""
    max_choices: int = 16
    """Largest `n` (answers per request)."""

    def __post_init__(self) -> None:
        if not (self.max_body_mb > 0 and self.read_timeout_s > 0 and self.max_choices >= 1):
            raise ValueError(f"chat server limits must be positive, got {self}")

    @property
    def max_body_bytes(self) -> int:
        return int(self.max_body_mb * _MB)


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.1"  # keep-alive, as the openai client expects
    # What a request line that cannot be parsed is taken for: an HTTP/0.9 answer has no status line,
    # and an HTTP/1.1 one tells the client what went wrong.
    default_request_version = "HTTP/1.1"

    def log_message(self, format: str, *args: object) -> None:
        logger.debug("%s %s", self.address_string(), format % args)

    def handle_one_request(self) -> None:
        """http.server's loop step, with every way a request can fail answered in JSON (408 if it stalls)."""
        # Idle time between requests on a kept-alive connection is not a stalled request: wait longer.
        self.connection.settimeout(IDLE_TIMEOUT_S)
        try:
            started = self.rfile.peek(1)
        except OSError:  # timed out idle, or the client hung up: no request, nothing to answer
            started = b""
        if not started:
            self.close_connection = True
            return
        self.connection.settimeout(self.server.chat.limits.read_timeout_s)
        self.command, self.requestline, self.request_version = "", "", ""  # what send_error reads if the line stalls
        try:
            self.raw_requestline = self.rfile.readline(65537)
            if len(self.raw_requestline) > 65536:
                return self.send_error(414, "the request line is longer than 64 KiB")
            if not self.parse_request():
                return  # parse_request has answered (through send_error)
            if (refusal := self._unauthorized()) is not None:
                return self._reject(refusal, unread_body=True, headers={"WWW-Authenticate": "Bearer"})
            method = getattr(self, f"do_{self.command}", None)
            if method is None:
                return self.send_error(405, f"method {self.command} is not supported; use GET or POST")
            method()
            self.wfile.flush()
        except TimeoutError:
            self._reject(InvalidRequest(
                f"the request line and headers did not arrive within {self._timeout_text()}; send the whole request",
                code="request_timeout", status=408), unread_body=True)
        except ConnectionError:
            logger.info("chat server: %s hung up mid-request", self.address_string())
            self.close_connection = True

    def handle_expect_100(self) -> bool:
        # Invite the body only when it will be read, so that a client with a body past the limit, or
        # without the key, gets its 413 or 401 before it sends anything.
        length = self.headers.get("Content-Length", "")
        if (_BYTE_COUNT.fullmatch(length) and int(length) <= self.server.chat.limits.max_body_bytes
                and self._unauthorized() is None):
            return super().handle_expect_100()
        return True

    def _unauthorized(self) -> InvalidRequest | None:
        """The 401 of a request without the server's API key (None: it carries the key, or none is set)."""
        key = self.server.chat.api_key
        if key is None:
            return None
        scheme, _, sent = self.headers.get("Authorization", "").strip().partition(" ")
        if scheme.lower() != "bearer" or not sent.strip():
            return InvalidRequest("this server needs an API key: send it as the header 'Authorization: Bearer KEY' "
                                  "(the api_key of an OpenAI client)", code="missing_api_key", status=401)
        if not hmac.compare_digest(sent.strip().encode(), key.encode()):  # in constant time: no timing hints
            return InvalidRequest("the API key sent is not this server's (the key itself is not repeated here); "
                                  "send the key the server was started with", code="invalid_api_key", status=401)
        return None

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """http.server's own rejections (bad request line or headers, unknown method) in the OpenAI shape."""
        text = message or self.responses.get(code, ("error",))[0]
        self._reject(InvalidRequest(f"{text}{f' ({explain})' if explain else ''}", code="bad_http", status=code),
                     unread_body=True)

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

    def _error(self, status: int, message: str, kind: str, code: str | None = None, param: str | None = None,
               headers: dict[str, str] | None = None) -> None:
        logger.warning("chat server: %s %s %s -> %d %s", self.address_string(), self.command or "-",
                       self.path if self.command else "-", status, message)
        self._json(status, {"error": {"message": message, "type": kind, "param": param, "code": code}}, headers)

    def _reject(self, error: InvalidRequest, unread_body: bool = False, headers: dict[str, str] | None = None) -> None:
        """Answer `error` (with `headers`); with `unread_body` the connection closes, after a lingering
        read of what the client still sends: closing on unread bytes resets the connection, and the
        reset can destroy the answer before the client reads it."""
        kind = {401: "authentication_error", 404: "not_found_error"}.get(error.status, "invalid_request_error")
        try:
            self._error(error.status, error.message, kind, error.code, error.param,
                        ({"Connection": "close"} if unread_body else {}) | (headers or {}))
            self.wfile.flush()
        except OSError:  # the client is gone, or stopped reading: nobody is left to answer
            unread_body = True
        if unread_body:
            self.close_connection = True
            self._discard_input()

    def _discard_input(self) -> None:
        """Read and drop what the client sends until it stops or the read timeout is spent."""
        deadline = time.monotonic() + self.server.chat.limits.read_timeout_s
        try:
            self.connection.shutdown(socket.SHUT_WR)  # the answer is complete: the client may close now
            while (left := deadline - time.monotonic()) > 0:
                self.connection.settimeout(left)
                if not self.connection.recv(1 << 16):
                    break
        except OSError:  # timed out or reset: either way the connection is done
            pass

    def _timeout_text(self) -> str:
        return f"{self.server.chat.limits.read_timeout_s:g} s (the server's read timeout, --read-timeout-s)"

    def _read_body(self) -> bytes:
        """The request body, read within the read timeout.

        Raises:
            InvalidRequest: no usable Content-Length (411/400), a body past the limit (413, left
                unread), or fewer bytes than declared within the read timeout (408).
        """
        limits = self.server.chat.limits
        if self.headers.get("Transfer-Encoding"):
            raise InvalidRequest("chunked request bodies are not supported; send the body with a Content-Length",
                                 code="length_required", status=411)
        declared = self.headers.get_all("Content-Length") or []
        if not declared:
            raise InvalidRequest("a Content-Length header is required", code="length_required", status=411)
        if len(set(declared)) > 1 or not _BYTE_COUNT.fullmatch(declared[0]):
            raise InvalidRequest(f"Content-Length must be one byte count, got {', '.join(map(repr, declared))}",
                                 code="invalid_content_length")
        length = int(declared[0])
        if length > limits.max_body_bytes:
            raise InvalidRequest(
                f"the request body is {length / _MB:.1f} MB, over this server's limit of {limits.max_body_mb:g} MB "
                "(--max-body-mb); send fewer or smaller images", code="body_too_large", status=413)
        deadline, chunks, received = time.monotonic() + limits.read_timeout_s, [], 0
        while received < length:
            try:
                self.connection.settimeout(max(deadline - time.monotonic(), 1e-3))
                chunk = self.rfile.read1(length - received)
            except TimeoutError:
                chunk = b""
            if not chunk:
                raise InvalidRequest(
                    f"the body ended after {received} of the {length} bytes its Content-Length declares (waited "
                    f"{self._timeout_text()}); send the whole body, or a Content-Length that matches it",
                    code="incomplete_body", status=408)
            chunks.append(chunk)
            received += len(chunk)
        return b"".join(chunks)

    def do_GET(self) -> None:
        if self.path.rstrip("/") != "/v1/models":
            return self._reject(InvalidRequest(f"no route GET {self.path}; GET /v1/models lists the model",
                                               code="not_found", status=404))
        chat = self.server.chat
        model = {"id": chat.model, "object": "model", "created": 0, "owned_by": "gymnast", **chat.card}
        self._json(200, {"object": "list", "data": [model]})

    def do_POST(self) -> None:
        try:
            body = self._read_body()  # read whatever the path, so that the connection stays usable
        except InvalidRequest as error:
            return self._reject(error, unread_body=True)
        if self.path.rstrip("/") != "/v1/chat/completions":
            return self._reject(InvalidRequest(f"no route POST {self.path}; POST /v1/chat/completions answers",
                                               code="not_found", status=404))
        chat = self.server.chat
        fault = chat.next_fault()
        if fault == "429":
            return self._error(429, "rate limited (injected fault)", "rate_limit_error", headers={"Retry-After": "0"})
        if fault == "500":
            return self._error(500, "server error (injected fault)", "server_error")
        if fault == "invalid_json":
            return self._send(200, b"{this is not json")
        if fault.startswith("slow:"):
            time.sleep(float(fault.removeprefix("slow:")))
        try:
            request = parse_chat_request(body, chat.limits.max_choices)
            contents = ["the robot looks nice" if fault == "garbage" else chat.answer(request)
                        for _ in range(request.choices)]
        except InvalidRequest as error:
            return self._reject(error)
        except Exception as error:  # a bug in the answer function: say so, and keep serving
            logger.exception("chat server: the answer function failed")
            return self._error(500, f"the model failed on this request ({error!r}); see the server's log",
                               "server_error")
        text, frames = request.text, request.frames
        prompt_tokens = len(text) // 4 + 85 * len(frames)  # rough: ~4 characters a token, 85 a small image
        completion_tokens = sum(len(content) // 4 + 1 for content in contents)
        self._json(200, {
            "id": f"chatcmpl-{uuid.uuid4().hex}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": request.model or chat.model,
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


def is_local(host: str) -> bool:
    """Whether `host` names this machine alone (a loopback address, or a name that resolves only to one)."""
    try:
        addresses = {info[4][0] for info in socket.getaddrinfo(host, None)}
    except (socket.gaierror, UnicodeError):  # a name that does not resolve: binding to it fails anyway
        return False
    return bool(addresses) and all(ipaddress.ip_address(address.split("%")[0]).is_loopback for address in addresses)


class ChatServer:
    """An OpenAI-compatible chat-completions server around an answer function.

    Args:
        answer: `answer(request)` gets a request's text (all text parts joined), its images, each
            (H, W, 3) uint8, and the cameras they were named under (`ChatRequest`), and returns the
            assistant's reply (or raises `InvalidRequest`, answered with its 4xx); called once per
            choice (`n`), from the server's threads, so it must be thread-safe.
        host: interface to listen on; an address other machines can reach needs `api_key`.
        port: port to listen on; 0 picks a free one (see `url`).
        faults: failures to inject, consumed one per chat request in order: "429", "500",
            "slow:SECONDS" (delay, then answer), "garbage" (a reply with no ANSWER line),
            "invalid_json" (a 200 whose body is not JSON).
        model: the model name that `GET /v1/models` lists.
        limits: the largest body and `n`, and the read timeout.
        api_key: the key every request must carry (``Authorization: Bearer KEY``); None: none needed.
        card: more fields of the model that `GET /v1/models` lists (what it expects of a request).

    Raises:
        ValueError: an empty `api_key`, or `host` reachable from other machines without one.

    Attributes:
        requests_served: chat-completion requests received so far, faulted ones included.
    """

    def __init__(self, answer: Answer, host: str = "127.0.0.1", port: int = 0, faults: Sequence[str] = (),
                 model: str = "gymnast-judge", limits: ChatLimits = ChatLimits(), api_key: str | None = None,
                 card: Mapping[str, object] | None = None) -> None:
        if api_key is not None and not api_key.strip():
            raise ValueError("the chat server's API key is empty; give a key, or none on this machine only")
        if api_key is None and not is_local(host):
            raise ValueError(f"refusing to serve on {host} without an API key: every machine that can reach that "
                             "address could send requests and read the answers; give a key (--api-key, or the "
                             "GYMNAST_JUDGE_API_KEY environment variable) or bind to 127.0.0.1")
        self.answer, self.host, self.model, self.limits, self.api_key = answer, host, model, limits, api_key
        self.card = dict(card or {})
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
