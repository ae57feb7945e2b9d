"""Action tokenizer: round trip within half a bin, ranges, persistence."""

import pytest
import torch

from gymnast.policy.action_tokenizer import ActionTokenizer


def test_round_trip_error_is_at_most_half_a_bin():
    tokenizer = ActionTokenizer()
    actions = torch.rand(10_000, 4) * 2 - 1
    error = (tokenizer.decode(tokenizer.encode(actions)) - actions).abs()
    assert error.max() <= tokenizer.bin_width.max() / 2 + 1e-6


def test_tokens_cover_all_bins_and_clip_out_of_range_actions():
    tokenizer = ActionTokenizer(low=(-1.0,), high=(1.0,), bins=256)
    tokens = tokenizer.encode(torch.tensor([[-5.0], [-1.0], [0.0], [1.0], [5.0]]))
    assert tokens.squeeze(1).tolist() == [0, 0, 128, 255, 255]


def test_uneven_ranges_bin_each_dimension_separately():
    tokenizer = ActionTokenizer(low=(0.0, -2.0), high=(1.0, 2.0), bins=4)
    assert tokenizer.decode(torch.tensor([[0, 3]])).tolist() == [[0.125, 1.5]]


def test_tokenizer_survives_a_dict_round_trip():
    tokenizer = ActionTokenizer(low=(-0.5, -1, -1, -1), high=(0.5, 1, 1, 1), bins=64)
    assert ActionTokenizer.from_dict(tokenizer.to_dict()) == tokenizer


def test_bad_ranges_and_shapes_are_refused():
    with pytest.raises(ValueError, match="high"):
        ActionTokenizer(low=(1.0,), high=(0.0,))
    with pytest.raises(ValueError, match=r"last dimension 4.*\(2, 3\)"):
        ActionTokenizer().encode(torch.zeros(2, 3))
