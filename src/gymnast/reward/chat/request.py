"""The body of a chat-completions request, checked field by field, and the error that rejects one.

`parse_chat_request` turns the bytes of `POST /v1/chat/completions` into the text, images and
number of choices the server answers, or raises `InvalidRequest` naming the field at fault (in the
`param` style of the OpenAI API: ``messages[0].content[1].image_url.url``) and what to send instead.

The protocol has no field that names an image, so a client that sends one image per camera names
them in text: a text part with a line ``Camera: NAME`` names the images after it, up to the next
such line (`ChatRequest.cameras`).
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import io
import json
import re
from typing import TypeVar

import numpy as np
from PIL import Image

# A decoded image costs 3 bytes a pixel whatever its compressed size, so a small file declaring a
# huge canvas could exhaust memory; robot cameras and VLM inputs stay far below this.
MAX_IMAGE_PIXELS = 4096 * 4096
_CAMERA = re.compile(r"^Camera:[ \t]*(\S.*?)\s*$", re.MULTILINE)  # a text line naming the images after it

T = TypeVar("T")


class InvalidRequest(Exception):
    """A request the server answers with a 4xx error in the OpenAI shape.

    Args:
        message: what is wrong and what to send instead; shown to the client as is.
        param: the field at fault (``messages[0].content``), or None for the request as a whole.
        code: a short machine-readable reason, such as ``invalid_image`` or ``body_too_large``.
        status: the HTTP status of the answer.
    """

    def __init__(self, message: str, param: str | None = None, code: str = "invalid_request",
                 status: int = 400) -> None:
        super().__init__(message)
        self.message, self.param, self.code, self.status = message, param, code, status


@dataclasses.dataclass(frozen=True)
class ChatRequest:
    """What the server needs of a well-formed chat-completions request."""

    text: str
    """The text parts of all messages, joined by newlines."""
    frames: list[np.ndarray]
    """The images of all messages in order, each (H, W, 3) uint8."""
    cameras: list[str | None]
    """The camera each image was named under: the last ``Camera: NAME`` line of the text before it
    (None where no text before it names one)."""
    choices: int
    """How many answers to return (`n`)."""
    model: str | None
    """The model the client asked for, if it named one."""


def parse_chat_request(body: bytes, max_choices: int) -> ChatRequest:
    """The request in a chat-completions body.

    Raises:
        InvalidRequest: the body is not JSON, a field is missing or of the wrong type, an image does
            not decode, or `n` is not an integer from 1 to `max_choices`.
    """
    if not body.strip():
        raise InvalidRequest("the request body is empty; send a JSON object with 'model' and 'messages'",
                             code="invalid_json")
    try:
        request = json.loads(body)
    except (ValueError, RecursionError) as error:  # UnicodeDecodeError is a ValueError; deep nesting recurses
        raise InvalidRequest(f"the request body is not valid JSON ({error}); send a JSON object with 'model' "
                             "and 'messages'", code="invalid_json") from None
    if not isinstance(request, dict):
        raise InvalidRequest(f"the request body must be a JSON object, got a JSON {_json_type(request)}",
                             code="invalid_type")
    model = request.get("model")
    if model is not None and not isinstance(model, str):
        raise InvalidRequest(f"'model' must be a string, got a JSON {_json_type(model)}", "model", "invalid_type")
    text, frames, cameras = read_messages(request.get("messages"))
    return ChatRequest(text, frames, cameras, _choices(request.get("n"), max_choices), model)


def read_messages(messages: object) -> tuple[str, list[np.ndarray], list[str | None]]:
    """The text parts of a request's `messages` joined by newlines, their images in order, and the
    camera each image was named under (`ChatRequest.cameras`).

    Raises:
        InvalidRequest: `messages` is not a non-empty list of {role, content} objects whose content
            is a string or a list of text and image_url parts.
    """
    if messages is None:
        raise InvalidRequest("'messages' is required: a list of {\"role\": ..., \"content\": ...} objects",
                             "messages", "missing_field")
    if not isinstance(messages, list) or not messages:
        got = "an empty list" if isinstance(messages, list) else f"a JSON {_json_type(messages)}"
        raise InvalidRequest(f"'messages' must be a non-empty list of {{\"role\": ..., \"content\": ...}} objects, "
                             f"got {got}", "messages", "invalid_type")
    texts, frames, cameras, camera = [], [], [], None
    for i, message in enumerate(messages):
        where = f"messages[{i}]"
        _require(message, dict, where, "an object with 'role' and 'content'")
        _require(message.get("role"), str, f"{where}.role", "a string such as \"user\"")
        content = message.get("content")
        if isinstance(content, str):
            content = [{"type": "text", "text": content}]
        elif content is not None:  # an assistant message may carry no content
            _require(content, list, f"{where}.content", "a string or a list of text and image_url parts")
        for j, part in enumerate(content or []):
            text, frame = _read_part(part, f"{where}.content[{j}]")
            if text is not None:
                texts.append(text)
                named = _CAMERA.findall(text)
                camera = named[-1] if named else camera
            if frame is not None:
                frames.append(frame)
                cameras.append(camera)
    return "\n".join(texts), frames, cameras


def _read_part(part: object, where: str) -> tuple[str | None, np.ndarray | None]:
    """(text, None) of a text part or (None, pixels) of an image_url part."""
    _require(part, dict, where, "an object with a 'type'")
    if part.get("type") == "text":
        return _require(part.get("text"), str, f"{where}.text", "a string"), None
    if part.get("type") == "image_url":
        image_url = _require(part.get("image_url"), dict, f"{where}.image_url", "an object with a 'url'")
        url = _require(image_url.get("url"), str, f"{where}.image_url.url", "a base64 data URL string")
        return None, decode_image(url, f"{where}.image_url.url")
    raise InvalidRequest(f"{where}.type must be \"text\" or \"image_url\", got {part.get('type')!r}",
                         f"{where}.type", "invalid_value")


def decode_image(url: str, where: str = "image_url.url") -> np.ndarray:
    """(H, W, 3) uint8 pixels of a `data:image/...;base64,...` URL (`where` names it in errors).

    Raises:
        InvalidRequest: not a base64 data URL, not base64, not a decodable image, or too large.
    """
    header, comma, payload = url.partition(",")
    if not (comma and header.startswith("data:image/") and header.endswith(";base64")):
        raise InvalidRequest(f"{where} must be a base64 data URL such as \"data:image/jpeg;base64,...\" (this "
                             f"server fetches no web addresses), got {url[:40]!r}", where, "invalid_image")
    try:
        data = base64.b64decode(payload, validate=True)
    except binascii.Error as error:
        raise InvalidRequest(f"{where} is not valid base64 ({error}); encode the image file's bytes with "
                             "standard base64", where, "invalid_image") from None
    try:
        with Image.open(io.BytesIO(data)) as image:
            width, height = image.size
            if width * height > MAX_IMAGE_PIXELS:
                raise InvalidRequest(f"{where} is {width}x{height} pixels, over the {MAX_IMAGE_PIXELS} this server "
                                     "decodes; send smaller frames", where, "image_too_large")
            return np.asarray(image.convert("RGB"))
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as error:  # what Pillow raises on bad data
        raise InvalidRequest(f"{where} holds {len(data)} bytes that do not decode as an image ({error}); send a "
                             "complete JPEG or PNG file", where, "invalid_image") from None


def _choices(n: object, max_choices: int) -> int:
    """The number of choices `n` asks for (1 when absent)."""
    if n is None:
        return 1
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= max_choices:
        raise InvalidRequest(f"'n' must be an integer from 1 to {max_choices} (the server's --max-choices), got "
                             f"{json.dumps(n)}", "n", "invalid_value")
    return n


def _require(value: object, kind: type[T], where: str, expected: str) -> T:
    """`value` if it is a `kind`, else an InvalidRequest naming the field, the expectation and what came."""
    if value is None:
        raise InvalidRequest(f"{where} is required: {expected}", where, "missing_field")
    if not isinstance(value, kind):
        raise InvalidRequest(f"{where} must be {expected}, got a JSON {_json_type(value)}", where, "invalid_type")
    return value


def _json_type(value: object) -> str:
    """The JSON name of a decoded value's type (object, array, string, number, boolean, null)."""
    names = {dict: "object", list: "array", str: "string", bool: "boolean", int: "number", float: "number"}
    return "null" if value is None else names.get(type(value), type(value).__name__)
