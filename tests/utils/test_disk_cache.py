"""The on-disk array cache, and the sentence embeddings it keeps for every process."""

import logging

import numpy as np
import pytest
import torch

from gymnast.policy import text
from gymnast.utils.disk_cache import CACHE_ENV, ArrayCache, cache_root


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    text._disk_cache.cache_clear()
    yield tmp_path / "cache"
    text._disk_cache.cache_clear()


def test_values_round_trip_and_bad_files_count_as_missing(cache_dir):
    cache = ArrayCache("things/v1")
    assert cache.get("a", (3,)) is None
    cache.put("a", np.array([1.0, 2.0, 3.0], dtype=np.float32))
    value = cache.get("a", (3,))
    assert value.dtype == np.float32 and value.tolist() == [1.0, 2.0, 3.0]
    assert ArrayCache("things/v2").get("a", (3,)) is None  # another namespace, another value
    assert cache.get("a", (4,)) is None  # a value of the wrong shape is not used
    cache.path("a").write_bytes(b"not an array")
    assert cache.get("a", (3,)) is None
    assert not [p for p in cache.directory.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("setting", ["", "off"])
def test_the_variable_turns_the_cache_off(monkeypatch, setting):
    monkeypatch.setenv(CACHE_ENV, setting)
    assert cache_root() is None
    cache = ArrayCache("things")
    cache.put("a", np.zeros(2))
    assert cache.get("a", (2,)) is None


def test_default_place_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache_root() == tmp_path / "gymnast"


def test_an_unwritable_cache_is_given_up_with_a_warning(tmp_path, monkeypatch, caplog):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv(CACHE_ENV, str(blocker / "cache"))  # its parent is a file: mkdir fails
    cache = ArrayCache("things")
    with caplog.at_level(logging.WARNING):
        cache.put("a", np.zeros(2))
    assert "cannot write the cache" in caplog.text and CACHE_ENV in caplog.text
    assert cache.get("a", (2,)) is None


def test_a_sentence_embedded_once_is_read_back_without_the_encoder(cache_dir, monkeypatch):
    sentence = "open the drawer on the left"
    first = text.InstructionEncoder()([sentence])[0]
    assert list(cache_dir.glob("sentences/*/*.npy"))

    def no_encoder():
        raise AssertionError("the encoder was loaded although the embedding was on disk")

    monkeypatch.setattr(text, "_sentence_model", no_encoder)
    second = text.InstructionEncoder()([sentence])[0]  # a new encoder: nothing in its memory
    assert torch.equal(first, second)
    assert abs(float(second.norm()) - 1.0) < 1e-5
