"""The WorldGym correlation: textbook values, and None where a correlation is undefined."""

import numpy as np
import pytest

from gymnast.experiment.worldgym import correlation


def test_pearson_and_spearman_match_their_definitions():
    imagined, real = [0.1, 0.4, 0.35, 0.8, 0.6, 0.2], [0.0, 0.3, 0.5, 0.9, 0.55, 0.1]
    result = correlation(imagined, real)
    assert result["pearson"] == pytest.approx(np.corrcoef(imagined, real)[0, 1])
    ranks = lambda v: np.argsort(np.argsort(v))
    assert result["spearman"] == pytest.approx(np.corrcoef(ranks(imagined), ranks(real))[0, 1])


def test_a_reversed_ranking_is_perfectly_anticorrelated():
    assert correlation([0.1, 0.2, 0.3], [0.9, 0.5, 0.4])["spearman"] == pytest.approx(-1.0)


@pytest.mark.parametrize("imagined, real", [([0.1, 0.2], [0.3, 0.4]), ([0.5, 0.5, 0.5], [0.1, 0.2, 0.3]),
                                            ([0.1, 0.2, 0.3], [0.0, 0.0, 0.0])])
def test_too_few_policies_or_a_constant_side_give_no_correlation(imagined, real):
    assert correlation(imagined, real) == {"pearson": None, "spearman": None}


def test_mismatched_lengths_are_an_error():
    with pytest.raises(ValueError, match="3 imagined estimates but 2 real"):
        correlation([0.1, 0.2, 0.3], [0.1, 0.2])
