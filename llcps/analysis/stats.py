"""Generic statistics over seeds: percent change, bootstrap intervals, paired and
unpaired tests, and Holm's correction over every p-value a report makes.

Nothing here knows the experiment: inputs are arrays (one value per seed) and rows
with p-values. Randomness comes from an explicit seed; :func:`cell_rng` gives each
cell its own stream derived from its key, so a cell's interval does not depend on
which other cells are in the table.
"""

from __future__ import annotations

import math
import warnings
import zlib
from dataclasses import replace
from typing import Any, Callable, Iterable

import numpy as np
from scipy import stats as sps

DEFAULT_RESAMPLES = 10_000
ALPHA = 0.05


def pct_change(update: float | np.ndarray, reset: float | np.ndarray) -> float | np.ndarray:
    """The paper's "% change with updates": ``100 * (update - reset) / reset``.

    Zero denominator: if both are 0 the change is 0 (neither needed exploration);
    if only ``reset`` is 0 the change is +inf (or -inf for a negative ``update``),
    an unbounded increase rather than a missing value.
    """
    u = np.asarray(update, dtype=float)
    r = np.asarray(reset, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 100.0 * (u - r) / r
    zero = r == 0
    out = np.where(zero & (u == 0), 0.0, out)
    out = np.where(zero & (u != 0), np.copysign(np.inf, u), out)
    return float(out) if out.ndim == 0 else out


def cell_rng(seed: int, *key: object) -> np.random.Generator:
    """A generator for one cell: the run seed plus a stable hash of the cell's key."""
    digest = zlib.crc32("|".join(map(str, key)).encode("utf-8"))
    return np.random.default_rng([int(seed), digest])


def _percentile_bootstrap(
    data: tuple[np.ndarray, ...], statistic: Callable[..., Any], *, paired: bool, rng: np.random.Generator, resamples: int, level: float
) -> tuple[float, float]:
    """A percentile interval from ``scipy.stats.bootstrap`` (NaN bounds when the resamples are degenerate)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # degenerate or infinite resamples: the bounds say so themselves
        result = sps.bootstrap(
            data,
            statistic,
            paired=paired,
            vectorized=True,
            n_resamples=resamples,
            confidence_level=level,
            method="percentile",
            rng=rng,
        )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def bootstrap_pct_change_ci(
    update: np.ndarray,
    reset: np.ndarray,
    *,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap interval of :func:`pct_change` of the means, resampling seeds as pairs.

    Pairs are kept together because update and reset of one seed share their start;
    resampling them independently would ignore that and widen the interval.
    Returns ``(nan, nan)`` for fewer than two pairs (no spread to resample).
    """
    u = np.asarray(update, dtype=float)
    r = np.asarray(reset, dtype=float)
    if u.shape != r.shape or u.ndim != 1:
        raise ValueError("update and reset must be 1-d arrays of equal length (one value per seed)")
    if u.size < 2:
        return (math.nan, math.nan)
    if np.all(u == u[0]) and np.all(r == r[0]):  # every resample is the estimate itself
        value = float(pct_change(u[0], r[0]))
        return (value, value)

    def change(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.asarray(pct_change(a.mean(axis=axis), b.mean(axis=axis)))

    return _percentile_bootstrap((u, r), change, paired=True, rng=rng, resamples=resamples, level=level)


def bootstrap_mean_ci(
    values: np.ndarray, *, rng: np.random.Generator, resamples: int = DEFAULT_RESAMPLES, level: float = 0.95
) -> tuple[float, float]:
    """Percentile bootstrap interval of a mean; ``(nan, nan)`` for fewer than two values."""
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return (math.nan, math.nan)
    if np.all(v == v[0]):
        return (float(v[0]), float(v[0]))
    return _percentile_bootstrap((v,), np.mean, paired=False, rng=rng, resamples=resamples, level=level)


def paired_wilcoxon(update: np.ndarray, reset: np.ndarray) -> tuple[float, str]:
    """Two-sided Wilcoxon signed-rank p-value over seeds, and why it is missing when it is.

    Zero differences are dropped (Wilcoxon's convention). Returns ``(nan, reason)``
    for fewer than two pairs or when every difference is zero (no test possible).
    """
    u = np.asarray(update, dtype=float)
    r = np.asarray(reset, dtype=float)
    if u.size < 2:
        return (math.nan, f"fewer than 2 paired seeds (n={u.size})")
    diff = u - r
    if np.all(diff == 0):
        return (math.nan, "all paired differences are zero")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = sps.wilcoxon(u, r, zero_method="wilcox", alternative="two-sided")
    return (float(result.pvalue), "")


def mann_whitney(a: np.ndarray, b: np.ndarray) -> tuple[float, str]:
    """Two-sided Mann-Whitney U p-value for unpaired samples, with a reason when missing."""
    x = np.asarray(a, dtype=float)
    y = np.asarray(b, dtype=float)
    if x.size < 2 or y.size < 2:
        return (math.nan, f"fewer than 2 values on a side (n={x.size} vs {y.size})")
    if np.all(x == x[0]) and np.all(y == x[0]):
        return (math.nan, "all values are equal")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = sps.mannwhitneyu(x, y, alternative="two-sided")
    return (float(result.pvalue), "")


def holm(p_values: Iterable[float]) -> list[float]:
    """Holm-adjusted p-values (``statsmodels``); NaN stays NaN and is not counted in the family."""
    from statsmodels.stats.multitest import multipletests

    p = [float(v) for v in p_values]
    finite = [i for i, v in enumerate(p) if not math.isnan(v)]
    out = [math.nan] * len(p)
    if finite:
        adjusted = multipletests([p[i] for i in finite], alpha=ALPHA, method="holm")[1]
        for i, value in zip(finite, adjusted):
            out[i] = float(value)
    return out


def adjust(families: Iterable[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
    """Holm's correction over every p-value of several tuples of rows at once.

    A report that tests many cells must correct over all of them together (update vs
    reset, censoring-aware comparisons, model vs random order), or its significant
    findings are mostly luck. Each row needs ``p_value`` and ``p_adjusted`` or ``p_holm``.

    Returns:
        The tuples in the same order, each row with its adjusted p-value set.
    """
    groups = [tuple(g) for g in families]
    adjusted = iter(holm(row.p_value for g in groups for row in g))
    return [
        tuple(replace(row, **{"p_adjusted" if hasattr(row, "p_adjusted") else "p_holm": next(adjusted)}) for row in g)
        for g in groups
    ]


__all__ = [
    "ALPHA",
    "DEFAULT_RESAMPLES",
    "adjust",
    "bootstrap_mean_ci",
    "bootstrap_pct_change_ci",
    "cell_rng",
    "holm",
    "mann_whitney",
    "paired_wilcoxon",
    "pct_change",
]
