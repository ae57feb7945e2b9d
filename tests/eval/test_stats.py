"""Wilson score intervals: published references, edge cases, and coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gymnast.eval.stats import success_summary, wilson_interval


@pytest.mark.parametrize(
    ("successes", "n", "low", "high"),
    [
        # Hand-computed: centre (p + z^2/2n) / (1 + z^2/n), half-width z/(1 + z^2/n) sqrt(p(1-p)/n + z^2/4n^2).
        (0, 10, 0.0, 0.2775),
        (5, 10, 0.2366, 0.7634),
        (10, 10, 0.7225, 1.0),
        # Newcombe (1998), Statistics in Medicine 17:857, Table I, method 3 (score, no correction).
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
    ],
)
def test_wilson_matches_published_and_hand_computed_values(successes, n, low, high):
    assert wilson_interval(successes, n) == pytest.approx((low, high), abs=5e-5)


def test_no_successes_give_an_interval_starting_exactly_at_zero_with_the_closed_form_top():
    z = 1.96
    assert wilson_interval(0, 10) == (0.0, pytest.approx(z**2 / (10 + z**2)))
    assert wilson_interval(10, 10) == (pytest.approx(10 / (10 + z**2)), 1.0)


def test_interval_contains_the_observed_rate_and_stays_inside_zero_one():
    for n in range(1, 41):
        for k in range(n + 1):
            low, high = wilson_interval(k, n)
            assert 0.0 <= low <= k / n <= high <= 1.0
            assert high - low > 0.0  # never claims certainty


def test_interval_is_symmetric_under_swapping_successes_and_failures():
    for n in (1, 7, 50):
        for k in range(n + 1):
            low, high = wilson_interval(k, n)
            mirror_low, mirror_high = wilson_interval(n - k, n)
            assert low == pytest.approx(1.0 - mirror_high) and high == pytest.approx(1.0 - mirror_low)


def test_interval_narrows_with_more_episodes_and_widens_with_confidence():
    widths = [np.subtract(*wilson_interval(n // 2, n)[::-1]) for n in (10, 40, 160, 640)]
    assert all(a > b for a, b in zip(widths, widths[1:]))
    assert np.subtract(*wilson_interval(5, 10, z=2.576)[::-1]) > np.subtract(*wilson_interval(5, 10, z=1.0)[::-1])


def test_coverage_is_close_to_the_nominal_95_percent():
    n = 50
    bounds = [wilson_interval(k, n) for k in range(n + 1)]

    def coverage(p: float) -> float:  # exact: the binomial probability of an interval containing p
        return sum(math.comb(n, k) * p**k * (1 - p) ** (n - k) for k, (lo, hi) in enumerate(bounds) if lo <= p <= hi)

    everywhere = [coverage(p) for p in np.linspace(0.01, 0.99, 99)]
    away_from_edges = [coverage(p) for p in np.linspace(0.1, 0.9, 81)]
    assert 0.94 <= np.mean(everywhere) <= 0.96
    assert min(away_from_edges) >= 0.92


def test_invalid_counts_are_clear_errors():
    with pytest.raises(ValueError, match="at least one episode"):
        wilson_interval(0, 0)
    with pytest.raises(ValueError, match="successes must be in"):
        wilson_interval(11, 10)
    with pytest.raises(ValueError, match="successes must be in"):
        wilson_interval(-1, 10)
    with pytest.raises(ValueError, match="z must be positive"):
        wilson_interval(1, 10, z=0.0)


def test_success_summary_counts_records_and_refuses_none():
    summary = success_summary([{"success": True}, {"success": False}, {"success": True}, {"success": True}])
    assert summary["success"] == 0.75 and summary["episodes"] == 4 and summary["successes"] == 3
    assert (summary["ci_low"], summary["ci_high"]) == wilson_interval(3, 4)
    with pytest.raises(ValueError, match="at least one episode"):
        success_summary([])
