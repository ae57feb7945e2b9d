"""How reports write rates: one place, so every table in an experiment's report reads the same."""

from __future__ import annotations


def pct(value: float | None) -> str:
    """A rate in [0, 1] as a percentage with one decimal; '-' where there is none."""
    return "-" if value is None else f"{100 * value:.1f}%"


def ci(row: dict) -> str:
    """The 95% interval of a row that carries `ci_low` and `ci_high`."""
    return f"[{pct(row['ci_low'])}, {pct(row['ci_high'])}]"
