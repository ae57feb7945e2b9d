"""How reports write their figures (rates, ratios, wall times): one place, so every table in an
experiment's report and its printed summary read the same."""

from __future__ import annotations


def pct(value: float | None) -> str:
    """A rate in [0, 1] as a percentage with one decimal; '-' where there is none."""
    return "-" if value is None else f"{100 * value:.1f}%"


def ci(row: dict) -> str:
    """The 95% interval of a row that carries `ci_low` and `ci_high`."""
    return f"[{pct(row['ci_low'])}, {pct(row['ci_high'])}]"


def number(value: float | None) -> str:
    """A figure with two decimals; 'undefined' where there is none (a correlation of equal values)."""
    return "undefined" if value is None else f"{value:.2f}"


def ratio(value: float | None) -> str:
    """One success over another, as '1.25x'; 'undefined' where the one below is zero."""
    return "undefined (division by zero success)" if value is None else f"{value:.2f}x"


def wall_time(row: dict) -> str:
    """An arm's wall time in minutes; 'reused' for a stage that reused another run and logged none."""
    if row["wall_s"] is None:
        return "reused" if row["reused"] else "-"
    return f"{row['wall_s'] / 60:.1f} min" + (" (reused run's log)" if row["reused"] else "")
