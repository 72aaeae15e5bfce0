"""The experiment statistics against values worked out by hand on small fixed tables."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from llcps.analysis import cumulative, figure2, paper, stats, versus_random
from llcps.experiments.design import PAPER_SCENARIOS, Sequence, Cell
from llcps.analysis.results import ResultsTable
from llcps.experiments.rows import ResultRow


def _row(model: str, measure: str, size: int, condition: str, seed: int, scenario: str, trials: int) -> ResultRow:
    seq = Sequence("paper", Cell(model, measure, size, condition), seed)
    return ResultRow(
        preset="paper",
        model=model,
        measure=measure,
        pretrain_size=size,
        condition=condition,
        seed=seed,
        scenario=scenario,
        solved=trials < 100,
        exploration_trials=trials,
        sim_seconds=trials * 0.5,
        wall_seconds=trials * 0.25,
        episode_id=None,
        branch=seq.episode_branch(scenario),
    )


# Three seeds of nb / most-changes / 4 points in scenario 2:
#   update 12, 20, 35 ; reset 20, 30, 31 -> differences -8, -10, +4.
UPDATE = (12, 20, 35)
RESET = (20, 30, 31)


def _fixed_table() -> ResultsTable:
    rows = []
    for seed, (u, r) in enumerate(zip(UPDATE, RESET)):
        rows.append(_row("nb", "most-changes", 4, "update", seed, "scenario2", u))
        rows.append(_row("nb", "most-changes", 4, "reset", seed, "scenario2", r))
    return ResultsTable(rows)


def _exact_signed_rank_p(diffs: list[float]) -> float:
    """Two-sided exact p by enumerating every sign assignment (no ties, no zeros)."""
    ranks = np.argsort(np.argsort(np.abs(diffs))) + 1
    observed = sum(rank for rank, d in zip(ranks, diffs) if d > 0)
    n = len(diffs)
    centre = n * (n + 1) / 4
    sums = [sum(r for r, s in zip(ranks, signs) if s) for signs in itertools.product((0, 1), repeat=n)]
    return sum(abs(w - centre) >= abs(observed - centre) for w in sums) / len(sums)


def test_pct_change_and_zero_denominator() -> None:
    assert stats.pct_change(15, 20) == pytest.approx(-25.0)
    assert stats.pct_change(30, 20) == pytest.approx(50.0)
    assert stats.pct_change(0, 0) == 0.0
    assert stats.pct_change(5, 0) == math.inf
    np.testing.assert_array_equal(
        stats.pct_change(np.array([0.0, 2.0, 1.0]), np.array([0.0, 0.0, 2.0])), [0, np.inf, -50]
    )


def test_figure2_row_matches_hand_computation() -> None:
    (row,) = figure2.figure2_table(_fixed_table(), resamples=10_000, seed=3)
    assert (row.model, row.measure, row.pretrain_size, row.scenario, row.n_seeds) == (
        "nb",
        "most-changes",
        4,
        "scenario2",
        3,
    )
    assert row.mean_update == pytest.approx(67 / 3)
    assert row.mean_reset == pytest.approx(27.0)
    assert row.pct_change == pytest.approx(100 * (67 / 3 - 27) / 27)  # -17.28 %
    # Ranks of |d| = 8, 10, 4 are 2, 3, 1; W+ = 1 of a possible 6; two-sided exact p = 2 * 2/8.
    assert row.p_value == pytest.approx(0.5)
    assert row.p_value == pytest.approx(_exact_signed_rank_p([u - r for u, r in zip(UPDATE, RESET)]))
    assert row.p_reason == ""
    assert row.paper_pct_change == 640.0  # NB, most changes, no apriori training, scenario 2
    # Each "all three resampled pairs are the same seed" outcome has probability 1/27 > 2.5%,
    # so the percentile bounds are exactly the most extreme single-seed changes.
    assert row.ci_low == pytest.approx(stats.pct_change(12, 20))  # -40 %
    assert row.ci_high == pytest.approx(stats.pct_change(35, 31))  # +12.9 %
    assert row.ci_low <= row.pct_change <= row.ci_high


def test_bootstrap_is_reproducible_and_contains_the_estimate() -> None:
    rng = np.random.default_rng(0)
    u = rng.poisson(20, size=12).astype(float)
    r = rng.poisson(30, size=12).astype(float)
    first = stats.bootstrap_pct_change_ci(u, r, rng=stats.cell_rng(7, "a"))
    again = stats.bootstrap_pct_change_ci(u, r, rng=stats.cell_rng(7, "a"))
    other = stats.bootstrap_pct_change_ci(u, r, rng=stats.cell_rng(8, "a"))
    assert first == again
    assert first != other
    assert first[0] <= stats.pct_change(u.mean(), r.mean()) <= first[1]
    assert stats.bootstrap_pct_change_ci(u[:1], r[:1], rng=stats.cell_rng(0)) == pytest.approx(
        (math.nan, math.nan), nan_ok=True
    )


def test_wilcoxon_missing_cases_have_reasons() -> None:
    p, reason = stats.paired_wilcoxon(np.array([3.0, 4.0]), np.array([3.0, 4.0]))
    assert math.isnan(p) and "zero" in reason
    p, reason = stats.paired_wilcoxon(np.array([3.0]), np.array([5.0]))
    assert math.isnan(p) and "fewer than 2" in reason
    # Five differences of one sign: exact two-sided p = 2 / 2**5.
    p, reason = stats.paired_wilcoxon(np.array([3.0, 6, 9, 1, 5]), np.array([1.0, 2, 3, 0, 1]))
    assert p == pytest.approx(0.0625) and reason == ""


def test_mann_whitney_hand_value() -> None:
    # Complete separation of 3 vs 3: one arrangement of C(6,3) = 20 at each extreme.
    p, _ = stats.mann_whitney(np.array([1.0, 2, 3]), np.array([4.0, 5, 6]))
    assert p == pytest.approx(0.1)
    assert math.isnan(stats.mann_whitney(np.array([1.0, 1.0]), np.array([1.0, 1.0]))[0])


def test_holm_adjustment() -> None:
    adjusted = stats.holm([0.01, 0.04, 0.03, math.nan])
    assert adjusted[:3] == pytest.approx([0.03, 0.06, 0.06])
    assert math.isnan(adjusted[3])


def test_paper_table_and_its_reductions() -> None:
    assert paper.PAPER_FIGURE2[("nn", "least-destructive", 200, "scenario2")] == 182.0
    assert paper.PAPER_FIGURE2[("nb", "most-positive-changes", 4, "scenario3")] == -87.0
    summary = {(r.pretrain_size, r.model): r for r in figure2.reduction_summary(paper.paper_cells())}
    # Counted by hand from Figure 2: 6 decreases and 3 zeros of 16 with 200 points,
    # 10 decreases and 3 zeros with 4 (the caption's 81% is "reduced or unchanged").
    assert (summary[200, None].n_reduced, summary[200, None].n_unchanged, summary[200, None].n_cells) == (6, 3, 16)
    assert (summary[4, None].n_reduced, summary[4, None].n_unchanged) == (10, 3)
    assert summary[4, None].fraction_not_increased == pytest.approx(0.8125)
    assert summary[200, "nb"].fraction_reduced == pytest.approx(0.5)


def test_figure2_pairs_seeds_and_the_report_adjusts_every_comparison_together() -> None:
    rows = list(_fixed_table())
    # Scenario 1 under both conditions, and an unpaired update seed that must be ignored.
    for seed, (u, r) in enumerate([(5, 5), (6, 9), (7, 7)]):
        rows.append(_row("nb", "most-changes", 4, "update", seed, "scenario1", u))
        rows.append(_row("nb", "most-changes", 4, "reset", seed, "scenario1", r))
    rows.append(_row("nb", "most-changes", 4, "update", 9, "scenario2", 1000))
    table = ResultsTable(rows)
    by_scenario = {r.scenario: r for r in figure2.figure2_table(table, resamples=500)}
    assert by_scenario["scenario2"].n_seeds == 3
    assert by_scenario["scenario2"].mean_update == pytest.approx(67 / 3)
    assert all(math.isnan(r.p_holm) for r in by_scenario.values())  # the report corrects, over all its tests
    assert (by_scenario["scenario1"].p_value, by_scenario["scenario2"].p_value) == pytest.approx((1.0, 0.5))
    (adjusted,) = stats.adjust([tuple(by_scenario.values())])
    # Holm by hand: 0.5 x 2 = 1.0, then max(1.0, 1.0 x 1) = 1.0
    assert [r.p_holm for r in adjusted] == pytest.approx([1.0, 1.0])
    assert by_scenario["scenario1"].pct_change == pytest.approx(100 * (18 - 21) / 21)
    assert not by_scenario["scenario1"].identical  # seed 1: 6 against 9
    one_seed = ResultsTable(
        [_row("nb", "most-changes", 4, c, 0, "scenario1", 5) for c in ("update", "reset")]
    )  # too few seeds for a test, but identical all the same
    (control,) = figure2.figure2_table(one_seed, resamples=10)
    assert control.identical and math.isnan(control.p_value)
    assert [r.scenario for r in figure2.figure2_table(table, resamples=500)] == ["scenario1", "scenario2"]
    assert figure2.figure2_table(table, resamples=500, seed=1) == figure2.figure2_table(table, resamples=500, seed=1)


def test_random_comparison_paired_and_pooled() -> None:
    rows = list(_fixed_table())
    for seed, trials in enumerate((40, 50, 60)):
        rows.append(_row("random", "most-changes", 4, "update", seed, "scenario2", trials))
    table = ResultsTable(rows)

    def same_cell(comparisons):  # the others fall back to random's rows of the scenario
        return [c for c in comparisons if (c.pretrain_size, c.condition, c.scenario) == (4, "update", "scenario2")]

    (cmp,) = same_cell(versus_random.random_comparison(table))
    assert (cmp.model, cmp.condition, cmp.test, cmp.n_model, cmp.n_random) == ("nb", "update", "wilcoxon", 3, 3)
    assert cmp.median_model == 20 and cmp.median_random == 50
    assert cmp.pct_change_median == pytest.approx(-60.0)
    assert cmp.p_value == pytest.approx(0.25)  # three negative differences: 2 * 1/8
    # Random under another measure only: pooled, unpaired.
    other = ResultsTable(
        [r for r in table if r.model != "random"]
        + [_row("random", "least-destructive", 4, "update", s, "scenario2", t) for s, t in enumerate((40, 50, 60))]
    )
    (pooled,) = same_cell(versus_random.random_comparison(other))
    assert pooled.test == "mann-whitney"
    assert pooled.p_value == pytest.approx(0.1)  # 12, 20, 35 all below 40, 50, 60
    assert versus_random.random_comparison(_fixed_table()) == ()


def test_best_measure_against_random_from_another_pretraining_size() -> None:
    rows = []
    for seed in range(3):
        rows.append(_row("nb", "most-changes", 200, "reset", seed, "scenario2", 30 + seed))
        rows.append(_row("nb", "least-destructive", 200, "reset", seed, "scenario2", 10 + seed))
        rows.append(_row("nn", "least-destructive", 200, "update", seed, "scenario2", 1 + seed))  # not reset
        rows.append(_row("random", "most-changes", 4, "reset", seed, "scenario2", 40 + 10 * seed))
    comparisons = versus_random.random_comparison(ResultsTable(rows))
    # random ran with 4 pretraining points only: its rows of the scenario are the baseline
    assert len(comparisons) == 3 and all(c.n_random == 3 and c.test == "mann-whitney" for c in comparisons)
    (best,) = versus_random.best_versus_random(comparisons)
    assert (best.model, best.measure, best.condition, best.median_model) == ("nb", "least-destructive", "reset", 11)
    assert best.median_random == 50 and best.pct_change_median == pytest.approx(-78.0)
    assert best.p_value == pytest.approx(0.1)  # 10, 11, 12 all below 40, 50, 60
    assert versus_random.best_versus_random(comparisons, condition="update")[0].model == "nn"


def test_cumulative_exploration_sums_along_the_sequence() -> None:
    rows = [
        _row("nb", "most-changes", 4, "update", seed, scenario, trials)
        for seed, per_scenario in enumerate([(1, 2, 3), (3, 4, 5)])
        for scenario, trials in zip(PAPER_SCENARIOS, per_scenario)
    ]
    # An incomplete sequence must not count.
    rows.append(_row("nb", "most-changes", 4, "update", 7, "scenario1", 100))
    points = cumulative.cumulative_exploration(ResultsTable(rows), resamples=200)
    assert [p.mean for p in points] == pytest.approx([2.0, 5.0, 9.0])
    assert all(p.n_seeds == 2 and p.ci_low <= p.mean <= p.ci_high for p in points)


def test_unknown_metric_is_a_project_error() -> None:
    from llcps.errors import LlcpsError

    with pytest.raises(LlcpsError, match="metric"):
        figure2.figure2_table(_fixed_table(), metric="joules")
