"""Censoring-aware statistics: Kaplan–Meier, restricted means and the log-rank test on
hand-worked values, and the update-vs-reset table with unsolved episodes censored."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_experiments_stats import _row

from llcps.analysis import survival
from llcps.analysis.results import ResultsTable


def test_kaplan_meier_by_hand() -> None:
    # resolved after 1, 3, 3, 5 trials; two episodes hit the budget of 5 unresolved
    km = survival.kaplan_meier([1, 3, 3, 5, 5, 5], [True, True, True, True, False, False], tau=5)
    assert km.times == (1.0, 3.0, 5.0)
    assert km.survival == pytest.approx((5 / 6, 5 / 6 * 3 / 5, 5 / 6 * 3 / 5 * 2 / 3))
    assert (km.n, km.events, km.median) == (6, 4, 3.0)
    assert all(lo <= s <= hi for lo, s, hi in zip(km.ci_low, km.survival, km.ci_high))
    # censoring only at the budget: the restricted mean is the capped mean, 1 + 2 x 5/6 + 2 x 1/2
    assert km.rmst == pytest.approx(22 / 6)
    # every episode resolved: S ends at 0, and so does its interval (it is undefined there)
    done = survival.kaplan_meier([1, 2, 2, 4], [True] * 4, tau=5)
    assert done.survival[-1] == 0 and done.ci_low[-1] == 0 and done.ci_high[-1] == 0
    assert all(lo <= s <= hi for lo, s, hi in zip(done.ci_low, done.survival, done.ci_high))
    unresolved = survival.kaplan_meier([5, 5], [False, False], tau=5)
    assert unresolved.median is None and unresolved.rmst == 5 and unresolved.survival == (1.0,)


def test_restricted_mean_is_not_the_capped_mean_when_censored_early() -> None:
    # one episode stopped unresolved after 2 trials, one resolved after 4: the capped mean says 3,
    # but the censored one was still unresolved at 2, so by Kaplan-Meier S = 1 until 4 and RMST = 4
    assert survival.restricted_mean([2, 4], [False, True], tau=6) == pytest.approx(4.0)
    assert survival.restricted_mean([2, 4], [True, True], tau=6) == pytest.approx(3.0)


def test_log_rank_by_hand() -> None:
    # A resolves after 1 and 2 trials, B after 3 and 4. Observed - expected for A:
    # t=1: 1 - 2/4 (variance 2*2*1*3/(16*3)); t=2: 1 - 1/3 (variance 1*2*1*2/(9*2)); later A is out of the risk set.
    o_minus_e = (1 - 0.5) + (1 - 1 / 3)
    variance = 0.25 + 2 / 9
    expected = math.erfc(math.sqrt(o_minus_e**2 / variance) / math.sqrt(2))
    p, reason = survival._logrank(np.array([1.0, 2.0]), np.array([True, True]), np.array([3.0, 4.0]), np.array([True, True]))
    assert reason == "" and p == pytest.approx(expected)
    same, why = survival._logrank(np.array([1.0, 2.0]), np.array([True, True]), np.array([1.0, 2.0]), np.array([True, True]))
    assert math.isnan(same) and "identical" in why


def test_update_against_reset_with_unsolved_episodes_censored() -> None:
    # _row marks 100 or more trials unsolved; the paper preset's budget is tau
    update = (10, 20, 150, 30, 40, 150)
    reset = (60, 150, 150, 80, 150, 90)
    rows = [_row("nb", "most-changes", 4, c, seed, "scenario2", t) for c, trials in (("update", update), ("reset", reset)) for seed, t in enumerate(trials)]
    (row,) = survival.survival_table(ResultsTable(rows), resamples=300, seed=0)
    assert (row.n_seeds, row.tau, row.solved_update, row.solved_reset) == (6, 150.0, 4, 3)
    assert row.rmst_update == pytest.approx(np.mean(update)) and row.rmst_reset == pytest.approx(np.mean(reset))
    assert (row.median_update, row.median_reset) == (30.0, 90.0)  # reset: S = 5/6, 4/6, 3/6 after 60, 80, 90
    assert row.rmst_diff_ci_low <= row.rmst_diff <= row.rmst_diff_ci_high and row.rmst_diff < 0
    assert 0 < row.p_value < 1 and math.isnan(row.p_adjusted)
    assert survival.survival_table(ResultsTable(rows), resamples=300, seed=0) == (row,)  # seeded
    curves = survival.survival_curves(ResultsTable(rows))
    assert [(c.condition, c.estimate.events) for c in curves] == [("update", 4), ("reset", 3)]


def test_a_whole_space_preset_is_censored_where_its_episodes_end() -> None:
    """A whole-space budget is a number no episode reaches: an unsolved episode stops
    when the candidates run out, so the horizon is the largest count observed."""
    paper = [_row("nb", "most-changes", 4, "update", seed, "scenario2", t) for seed, t in enumerate((10, 150))]
    assert survival.budget(paper) == 150.0  # the paper preset's budget of 150
    whole = [dataclasses.replace(r, preset="lifelong", solved=s) for r, s in zip(paper, (True, False))]
    assert survival.budget(whole) == 150.0  # not the 100,000 of WHOLE_SPACE
    assert survival.kaplan_meier([10, 150], [True, False], tau=survival.budget(whole)).tau == 150.0
