"""How a report writes numbers: percent changes as the paper prints them, p-values,
intervals and significance stars, alike in markdown, HTML, plots and the terminal."""

from __future__ import annotations

import math

from llcps.analysis.figure2 import Figure2Row
from llcps.analysis.stats import ALPHA


def format_pct(value: float | None) -> str:
    """A percent change as the paper prints it: ``-17%``, ``+inf%``, ``n/a``."""
    if value is None or math.isnan(value):
        return "n/a"
    if math.isinf(value):
        return "+inf%" if value > 0 else "-inf%"
    return f"{value:+.0f}%" if round(value) != 0 else "0%"


def format_num(value: float, digits: int = 1) -> str:
    """A number with ``digits`` decimals, or ``n/a``."""
    return "n/a" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def format_p(value: float, reason: str = "") -> str:
    """A p-value for a table: three decimals, ``<0.001``, or ``n/a`` with the reason."""
    if value is None or math.isnan(value):
        return f"n/a ({reason})" if reason else "n/a"
    return "<0.001" if value < 0.001 else f"{value:.3f}"


def format_ci(low: float, high: float) -> str:
    """A 95% interval of percent changes, or ``n/a``."""
    if math.isnan(low) or math.isnan(high):
        return "n/a"
    return f"[{format_pct(low)}, {format_pct(high)}]"


def format_median(value: float | None, tau: float) -> str:
    """A Kaplan–Meier median, ``>tau`` when fewer than half resolved."""
    return f">{tau:g}" if value is None else f"{value:g}"


def stars(row: Figure2Row) -> str:
    """``**`` below :data:`~llcps.analysis.stats.ALPHA` after Holm, ``*`` before it, else nothing."""
    return "**" if row.p_holm < ALPHA else "*" if row.significant else ""


def model_side_share(by_model: int, with_pick: int) -> str:
    """``7 of 10``: solved episodes the model side resolved, of those whose side is known;
    ``-`` for an ordering without sides."""
    return f"{by_model} of {with_pick}" if with_pick else "-"


__all__ = ["format_ci", "format_median", "format_num", "format_p", "format_pct", "model_side_share", "stars"]
