"""Which features of a LeRobot dataset gymnast reads, and which could be meant when one is missing.

LeRobot names a robot's actions ``action``, its state ``observation.state`` and each camera
``observation.images.<camera>``, but published datasets do not all follow it (``actions``,
``state``, ``image``, ``observation.image`` ...). `gymnast.data.lerobot_format.FeatureKeys` says
which features are the actions and the states (``--action-key``, ``--state-key``); a camera is
picked by its name or by its whole feature key (``--camera``). When a feature is not there, `FeatureNotFound` lists the features that
could be it, with their dtypes and shapes, and the flag that reads the likeliest.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Literal

from gymnast.data.deviations import Deviations
from gymnast.data.lerobot_format import CAMERA_PREFIX, DatasetError, image_key

CAMERA_DTYPES = ("video", "image")
FLOAT_DTYPES = ("float16", "float32", "float64")
Role = Literal["action", "state", "camera"]
FLAGS: dict[Role, str] = {"action": "--action-key", "state": "--state-key", "camera": "--camera"}
# LeRobot's bookkeeping columns: float vectors too, but never a robot's actions or state.
_BOOKKEEPING = ("timestamp", "next.reward")


class FeatureNotFound(DatasetError):
    """A feature gymnast reads is not in ``info.json``; the message lists the candidates and the flag."""


def camera_features(features: Mapping) -> list[str]:
    """Camera features in the order a default camera is chosen: video features, then image ones."""
    return [key for dtype in CAMERA_DTYPES for key, f in features.items() if isinstance(f, dict) and f.get("dtype") == dtype]


def camera_name(key: str) -> str:
    """A camera's name: ``observation.images.top`` -> ``top``; other keys (``image``) are their own name."""
    return key.removeprefix(CAMERA_PREFIX)


def camera_key(features: Mapping, camera: str, info_path: Path) -> str:
    """The feature of camera `camera`: ``observation.images.<camera>``, else the camera feature `camera`.

    Raises:
        FeatureNotFound: neither is there (the message lists the cameras and the flag).
    """
    key = _find_camera(features, camera)
    if key is None:
        raise FeatureNotFound(f"{info_path}: no feature {image_key(camera)!r} for camera {camera!r}"
                              + suggestion("camera", features))
    return key


def has_feature(features: Mapping, role: Role, key: str) -> bool:
    """Whether the dataset has feature `key` (for a camera: the camera named or keyed `key`)."""
    return _find_camera(features, key) is not None if role == "camera" else key in features


def vector_width(features: Mapping, key: str, role: Role, info_path: Path, taken: Collection[str] = ()) -> int:
    """The width of the vector feature `key` (the actions or the states; `taken`: features read as another).

    Raises:
        FeatureNotFound: no such feature (the message lists the candidates and the flag).
        DatasetError: its shape is not [N] with N > 0.
    """
    feature = features.get(key)
    if not isinstance(feature, dict):
        raise FeatureNotFound(f"{info_path}: no {key!r} feature in 'features'" + suggestion(role, features, taken))
    shape = feature.get("shape")
    if not (isinstance(shape, list) and len(shape) == 1 and isinstance(shape[0], int) and shape[0] > 0):
        raise DatasetError(f"{info_path}: features[{key!r}].shape is {shape!r}, expected [N] with N > 0 "
                           f"(the {role} vector)")
    return shape[0]


def candidates(features: Mapping, role: Role) -> list[str]:
    """The features that could be the `role`: float vectors for the actions and the states (those
    whose key names the role first), image and video features for a camera."""
    if role == "camera":
        return camera_features(features)
    vectors = [key for key, f in features.items() if isinstance(f, dict) and f.get("dtype") in FLOAT_DTYPES
               and isinstance(f.get("shape"), list) and len(f["shape"]) == 1 and key not in _BOOKKEEPING]
    return sorted(vectors, key=lambda key: role not in key.lower())  # stable: dataset order otherwise


def describe(features: Mapping, key: str) -> str:
    """One feature for people: ``'actions' (float32, 7)``, ``'image' (video, 96x96x3)``."""
    feature = features[key]
    shape = feature.get("shape")
    size = "x".join(map(str, shape)) if isinstance(shape, list) else repr(shape)
    return f"{key!r} ({feature.get('dtype')}, {size})"


def flag(role: Role, key: str) -> str:
    """The flag that reads feature `key` as the `role`, e.g. ``--action-key actions``, ``--camera top``."""
    return f"{FLAGS[role]} {camera_name(key) if role == 'camera' else key}"


def suggestion(role: Role, features: Mapping, taken: Collection[str] = ()) -> str:
    """``; candidates: ... - pass FLAG KEY`` for an error message (the features `taken` as another role
    left out), or what the dataset has instead."""
    found = [key for key in candidates(features, role) if key not in taken]
    if not found:
        kind = "image or video" if role == "camera" else "float vector"
        return f"; no {kind} feature could be the {role} (features: {', '.join(map(repr, features))})"
    return f"; candidates: {', '.join(describe(features, key) for key in found)} - pass {flag(role, found[0])}"


def _find_camera(features: Mapping, camera: str) -> str | None:
    """The camera feature named `camera` (short names first, as before whole keys were taken), or None."""
    return next((key for key in (image_key(camera), camera) if key in camera_features(features)), None)


def image_shape(feature: Mapping, key: str, info_path: Path, notes: Deviations) -> tuple[int, int, int]:
    """(H, W, 3) of a camera feature's frames as they are read (always RGB).

    LeRobot gives ``shape`` [H, W, C] (or channels first, named so). Published datasets may give it
    only in the stream description (``info`` or, in v2.0, ``video_info``: ``video.height``,
    ``video.width``, ``video.channels``), or give one channel (grayscale, depth) or four (RGBA);
    such frames are read as RGB, with a deviation recorded.

    Raises:
        DatasetError: no usable size anywhere (the message names the field and the fix).
    """
    shape, names = feature.get("shape"), feature.get("names")
    if isinstance(shape, list) and len(shape) == 3 and all(_positive_int(s) for s in shape):
        if isinstance(names, list) and names and names[0] in ("channel", "channels"):
            shape = [shape[1], shape[2], shape[0]]
    else:
        described = next((feature[k] for k in ("info", "video_info") if isinstance(feature.get(k), dict)), {})
        height, width = described.get("video.height"), described.get("video.width")
        if not (_positive_int(height) and _positive_int(width)):
            raise DatasetError(f"{info_path}: features[{key!r}].shape is {shape!r}, expected [H, W, 3]; give the "
                               f"camera's frame size there (or as video.height and video.width under its 'info')")
        channels = described.get("video.channels", 3)
        shape = [height, width, channels if _positive_int(channels) else 3]
        notes.add(info_path, f"features.{key}.shape", f"the shape of {key!r} is {feature.get('shape')!r}",
                  f"taken from its stream description: {shape}")
    if shape[2] != 3:
        if shape[2] not in (1, 2, 4):
            raise DatasetError(f"{info_path}: features[{key!r}] has {shape[2]} channels; a camera has 1 (grayscale, "
                               "depth), 3 (RGB) or 4 (RGBA)")
        kind = "grayscale or depth" if shape[2] < 3 else "RGBA"
        notes.add(info_path, f"features.{key}.shape", f"camera {key!r} has {shape[2]} channels ({kind})",
                  "read as RGB (grey repeated to 3 channels, alpha dropped)")
    return shape[0], shape[1], 3


def _positive_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0
