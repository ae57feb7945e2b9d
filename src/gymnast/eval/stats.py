"""Success rates with confidence intervals.

Evaluations here are small (tens of episodes per task) and success rates sit near 0 or 1, where
the textbook normal interval ``p +- z sqrt(p (1 - p) / n)`` collapses to zero width (at 0/10 it
claims certainty) and leaves [0, 1]. The Wilson score interval inverts the score test instead: it
stays inside [0, 1], is never empty, and its coverage stays close to the nominal level even for
small n (Brown, Cai & DasGupta 2001; Newcombe 1998, method 3).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval for a binomial success rate.

    Args:
        successes: episodes that succeeded, 0 <= successes <= n.
        n: episodes run, at least 1.
        z: standard normal quantile of the confidence level (1.96 for 95%).

    Returns:
        (low, high) with 0 <= low <= successes / n <= high <= 1; low is exactly 0 when nothing
        succeeded and high exactly 1 when everything did.

    Raises:
        ValueError: n < 1 (a rate over no episodes is undefined), successes outside [0, n], or z <= 0.
    """
    if n < 1:
        raise ValueError(f"wilson_interval needs at least one episode, got n={n}")
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in [0, n={n}], got {successes}")
    if not z > 0:
        raise ValueError(f"z must be positive, got {z}")
    p = successes / n
    z2 = z * z
    denominator = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denominator
    half_width = z / denominator * math.sqrt(p * (1.0 - p) / n + z2 / (4 * n * n))
    # At the edges the closed form is exact in theory, but rounding can put the bound a hair
    # inside (0, 1), and "the CI starts at 0" is what a reader checks for a policy that never succeeds.
    low = 0.0 if successes == 0 else max(0.0, centre - half_width)
    high = 1.0 if successes == n else min(1.0, centre + half_width)
    return low, high


def success_summary(records: Iterable[Mapping], z: float = 1.96) -> dict:
    """Success rate and Wilson interval over episode records.

    Args:
        records: episodes, each a mapping with a boolean ``success``.
        z: standard normal quantile of the confidence level.

    Returns:
        ``{"success", "ci_low", "ci_high", "episodes", "successes"}``.

    Raises:
        ValueError: no records.
    """
    outcomes = [bool(record["success"]) for record in records]
    if not outcomes:
        raise ValueError("success_summary needs at least one episode record, got none")
    successes = sum(outcomes)
    low, high = wilson_interval(successes, len(outcomes), z)
    return {
        "success": successes / len(outcomes),
        "ci_low": low,
        "ci_high": high,
        "episodes": len(outcomes),
        "successes": successes,
    }
