"""Experiments over any scenarios, and the leave-one-family-out preset: its statistics on
hand-worked numbers, its options, and a tiny grid end to end."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, replace
from pathlib import Path
from typing import Iterator

import pytest
from scipy import stats as sps
from typer.testing import CliRunner

from llcps.analysis.generalization import family_results, generalization_summary, geometric_mean, ratio
from llcps.analysis.results import ResultsTable, table_from_episodes
from llcps.analysis.stats import holm
from llcps.cli.main import app
from llcps.errors import LlcpsError, UnknownNameError
from llcps.experiments.design import PAPER_SCENARIOS, Cell, Sequence, parse_branch, scenario_rank
from llcps.experiments.holdout import pretraining_leaks
from llcps.experiments.presets import PRESETS, resolve_scenarios
from llcps.experiments.rows import ResultRow
from llcps.experiments.scheduler import expected_scenarios
from llcps.experiments.tasks import SequenceTask, plan_tasks
from llcps.jobs.experiment import run_experiment_job
from llcps.models.measures import MEASURES
from llcps.models.registry import WORLD_MODELS
from llcps.scenarios import SCENARIOS
from llcps.store import Store

DEFAULT = (WORLD_MODELS.default, MEASURES.default)


# -- scenario lists --------------------------------------------------------------------------
def test_paper_presets_keep_the_papers_scenarios_and_generalization_takes_every_shipped_one() -> None:
    for name in ("paper", "full", "smoke", "vs_random", "lifelong"):
        assert PRESETS[name].scenario_names() == PAPER_SCENARIOS
    assert PRESETS["generalization"].scenario_names() == tuple(SCENARIOS)
    assert len(SCENARIOS) >= 4


def test_scenarios_resolve_aliases_and_files_and_refuse_unknown_names(tmp_path: Path) -> None:
    assert resolve_scenarios(["container", "scenario4"]) == (("scenario2", "scenario2"), ("scenario4", "scenario4"))
    mine = tmp_path / "mine.toml"
    text = SCENARIOS["scenario4"].source.path.read_text(encoding="utf-8")  # type: ignore[union-attr]
    mine.write_text(text.replace('name = "scenario4"', 'name = "mine"').replace('alias = "wall"', ""), encoding="utf-8")
    assert resolve_scenarios([str(mine)]) == (("mine", str(mine.resolve())),)
    with pytest.raises(UnknownNameError) as info:
        resolve_scenarios(["scenario1", "nope"])
    assert "scenario4 (wall)" in (info.value.hint or "")
    with pytest.raises(LlcpsError, match="named twice"):
        resolve_scenarios(["scenario2", "container"])


def test_sequences_over_any_scenarios_name_parseable_branches() -> None:
    preset = PRESETS["generalization"].with_scenarios(["scenario4", "scenario1"])
    tasks = [t for t in plan_tasks(preset, [3], variants=True)]
    branches = [b for t in tasks[1:] for b in t.branches]  # type: ignore[union-attr]
    assert len(branches) == len(set(branches)) == (1 + preset.random_draws) * 2  # the default, and each random draw
    for name in branches:
        parsed = parse_branch(name)
        assert parsed is not None and parsed.scenario in ("scenario4", "scenario1") and parsed.sequence.variant == 3
    others = preset.with_others()
    assert others.conditions == ("others",)
    task = plan_tasks(others, [3], variants=True)[1]
    assert expected_scenarios(task) == {  # type: ignore[arg-type]
        task.sequence.episode_branch("scenario4"): ["scenario1", "scenario4"],  # type: ignore[union-attr]
        task.sequence.episode_branch("scenario1"): ["scenario4", "scenario1"],  # type: ignore[union-attr]
    }
    with pytest.raises(LlcpsError, match="no reset condition"):
        replace(PRESETS["lifelong"], conditions=("update",)).with_others()


def test_the_random_order_runs_in_several_draws_that_name_their_branch_and_seed_its_permutation() -> None:
    preset = PRESETS["generalization"].with_scenarios(["scenario1"])
    assert preset.random_draws == 3 and PRESETS["paper"].random_draws == 1
    sequences = preset.sequences([3], variants=True)
    random = [s for s in sequences if s.cell.model == "random"]
    assert [s.draw for s in random] == [0, 1, 2] and all(s.draw == 0 for s in sequences if s.cell.model != "random")
    assert [s.branch_name.rsplit("-", 2)[1:] for s in random] == [["s3", "v3"], ["v3", "d1"], ["v3", "d2"]]
    for seq in random:
        parsed = parse_branch(seq.episode_branch("scenario1"))
        assert parsed is not None and parsed.sequence == seq and parsed.sequence.draw == seq.draw
    seeds = [s.model_seed for s in random]
    assert seeds[0] is None  # draw 0 is the sequence's own seed: the runs before draws existed
    assert len(set(seeds[1:])) == 2 and all(0 <= x < 2**32 and x != 3 for x in seeds[1:])  # type: ignore[operator]
    assert preset.with_random_draws(1).sequences([3], variants=True) == tuple(s for s in sequences if s.draw == 0)
    assert preset.with_random_draws(None) == preset
    with pytest.raises(LlcpsError, match="random_draws"):
        preset.with_random_draws(0)
    with pytest.raises(LlcpsError, match="no random-order cell"):  # nothing there to draw again
        PRESETS["paper"].with_random_draws(3)
    assert PRESETS["paper"].with_random_draws(1).random_draws == 1
    with pytest.raises(LlcpsError, match="cannot name an experiment branch"):
        Sequence("generalization", Cell("random", DEFAULT[1], 200, "reset"), 0, 0, ("d2",))


def test_the_random_order_explores_in_the_papers_ordering_whatever_the_preset_explores_in() -> None:
    from llcps.cps.orderings import PAPER_ORDERING

    for ordering in (None, "hedged", "trial-and-error"):
        preset = PRESETS["generalization"].with_scenarios(["scenario1"]).with_ordering(ordering)
        tasks = [t for t in plan_tasks(preset, [3], variants=True) if isinstance(t, SequenceTask)]
        by_model = {(t.sequence.cell.model, t.sequence.draw): t.ordering for t in tasks}
        assert {o for (m, _), o in by_model.items() if m == "random"} == {PAPER_ORDERING}  # one baseline for all
        assert {o for (m, _), o in by_model.items() if m != "random"} == {preset.ordering}


def test_scenario_order_puts_the_papers_first_then_the_rest_by_name() -> None:
    assert sorted(["zeta", "scenario4", "scenario2", "scenario1"], key=scenario_rank) == ["scenario1", "scenario2", "scenario4", "zeta"]


@pytest.mark.parametrize(
    "argv, error",
    [
        (["--scenarios", "scenario1,nope"], "unknown scenario 'nope'"),
        (["--scenarios", ","], "no scenarios to run"),
        (["--scenarios", "scenario1,bucket"], "named twice"),
    ],
)
def test_bad_scenarios_are_one_error_line_and_create_no_store(tmp_path: Path, argv: list[str], error: str) -> None:
    db = tmp_path / "g.db"
    result = CliRunner().invoke(app, ["--db", str(db), "experiment", "run", "--preset", "generalization", *argv, "--create"])
    assert result.exit_code == 2, result.output
    assert error in result.stderr and "hint:" in result.stderr and "Traceback" not in result.output
    assert not db.exists()
    if "nope" in error:
        assert "scenario4 (wall)" in result.stderr


# -- the statistics on hand-worked numbers ---------------------------------------------------
def _row(model: str, family: str, variant: int, trials: int, solved: bool = True, condition: str = "reset", draw: int = 0) -> ResultRow:
    measure = DEFAULT[1]
    seq = Sequence("generalization", Cell(model, measure, 200, condition), variant, variant, (family,), draw=draw)
    return ResultRow(
        preset="generalization", model=model, measure=measure, pretrain_size=200, condition=condition, seed=variant,
        scenario=family, solved=solved, exploration_trials=trials, sim_seconds=1.0, wall_seconds=1.0, episode_id=None,
        branch=seq.episode_branch(family), variant=variant, draw=draw,
    )  # fmt: skip


@pytest.fixture
def table() -> ResultsTable:
    model, rnd = DEFAULT[0], "random"
    # family a: the model takes 2, 4, 6, 8, 10 trials, random 4, 4, 3, 16, 5 -> ratios .5, 1, 2, .5, 2
    # family b: the model 9 (unsolved at the budget 9) in variant 0, random resolves everything.
    a_model, a_random = [2, 4, 6, 8, 10], [4, 4, 3, 16, 5]
    b_model, b_random = [9, 3, 3, 3, 3], [1, 1, 6, 1, 1]
    rows = [_row(model, "scenario1", v, t) for v, t in enumerate(a_model)]
    rows += [_row(rnd, "scenario1", v, t) for v, t in enumerate(a_random)]
    rows += [_row(model, "scenario2", v, t, solved=v != 0) for v, t in enumerate(b_model)]
    rows += [_row(rnd, "scenario2", v, t) for v, t in enumerate(b_random)]
    return ResultsTable(rows)


def test_family_ratios_tests_and_overall_on_hand_worked_numbers(table: ResultsTable) -> None:
    results = family_results(table)
    a, b = results
    # The paper's ordering: default is model, measure and the default ordering (hedged).
    assert (a.family, b.family) == ("scenario1", "scenario2") and not a.default
    assert (a.median_model, a.median_random) == (6.0, 4.0)
    assert a.median_ratio == 1.0  # median of .5, 1, 2, .5, 2
    assert a.ratio_of_medians == 1.5
    assert b.median_ratio == 3.0 and b.ratio_of_medians == 3.0  # ratios 9, 3, .5, 3, 3
    p_a = sps.wilcoxon([2, 4, 6, 8, 10], [4, 4, 3, 16, 5]).pvalue
    p_b = sps.wilcoxon([9, 3, 3, 3, 3], [1, 1, 6, 1, 1]).pvalue
    assert a.p_value == pytest.approx(p_a) and b.p_value == pytest.approx(p_b)
    assert [a.p_holm, b.p_holm] == pytest.approx(holm([p_a, p_b]))
    # Censoring only in family b: Kaplan-Meier and log-rank there, not in a.
    assert a.logrank_p is None and a.km_median_model is None and a.unsolved_model == 0
    assert b.unsolved_model == 1 and b.logrank_p is not None and b.km_median_model == 3.0 and b.km_median_random == 1.0
    (overall,) = generalization_summary(results)
    assert overall.families == 2 and overall.worse_than_random == 1
    assert overall.geomean_ratio == pytest.approx(math.sqrt(1.0 * 3.0))


def test_the_random_order_of_a_variant_is_the_mean_of_its_draws(table: ResultsTable) -> None:
    """Two more draws of the random order in family a: 4, 4, 3, 16, 5 (draw 0), 8, 2, 3, 2, 7
    and 6, 6, 3, 3, 9 give means 6, 4, 3, 7, 7 -> ratios 1/3, 1, 2, 8/7, 10/7 against 2, 4, 6, 8, 10."""
    more = [_row("random", "scenario1", v, t, draw=1) for v, t in enumerate([8, 2, 3, 2, 7])]
    more += [_row("random", "scenario1", v, t, draw=2, solved=v != 3) for v, t in enumerate([6, 6, 3, 3, 9])]
    a, b = family_results(ResultsTable([*table, *more]))
    assert (a.random_draws, b.random_draws) == (3, 1)
    assert a.median_random == 6.0  # the median of the per-variant means
    assert a.median_ratio == pytest.approx(8 / 7)  # median of 1/3, 1, 2, 8/7, 10/7
    assert a.p_value == pytest.approx(sps.wilcoxon([2, 4, 6, 8, 10], [6, 4, 3, 7, 7]).pvalue)
    # The unsolved draw is censored: Kaplan-Meier and log-rank over every draw's episode.
    assert a.unsolved_random == 1 and a.logrank_p is not None
    assert replace(b, p_holm=0.0) == replace(family_results(table)[1], p_holm=0.0)  # one draw: as before


def _hedged(table: ResultsTable) -> list[ResultRow]:
    """The default model's rows again in the hedged ordering: twice the random order's trials in
    family a (every ratio 2), the random order's own in family b (every ratio 1)."""
    random = {(r.scenario, r.variant): r.exploration_trials for r in table if r.model == "random"}
    return [
        replace(r, ordering="hedged", solved=True, exploration_trials=random[(r.scenario, r.variant)] * (2 if r.scenario == "scenario1" else 1))
        for r in table
        if r.model != "random"
    ]


def test_two_orderings_against_one_random_set_are_two_row_groups(table: ResultsTable) -> None:
    both = ResultsTable([*table, *_hedged(table)])
    results = family_results(both)
    # The default's row group first.
    assert [(r.ordering, r.family) for r in results] == [
        ("hedged", "scenario1"), ("hedged", "scenario2"), ("ranked", "scenario1"), ("ranked", "scenario2"),
    ]  # fmt: skip
    ranked = [r for r in results if r.ordering == "ranked"]
    assert ranked == list(family_results(table))  # the ranked numbers do not change beside another ordering
    ha, hb = (r for r in results if r.ordering == "hedged")
    assert (ha.median_ratio, ha.ratio_of_medians, ha.median_random, ha.n) == (2.0, 2.0, 4.0, 5)
    assert (hb.median_ratio, hb.ratio_of_medians, hb.median_random) == (1.0, 1.0, 1.0)
    assert ha.default and hb.default and not any(r.default for r in ranked)  # default: model, measure and ordering
    # Holm within each ordering's families, not across the three tests made: hedged's only test
    # (b has no differences) keeps its p-value
    assert ha.p_value == pytest.approx(sps.wilcoxon([8, 8, 6, 32, 10], [4, 4, 3, 16, 5]).pvalue)
    assert ha.p_holm == ha.p_value and math.isnan(hb.p_value) and math.isnan(hb.p_holm)
    overall = {r.ordering: r for r in generalization_summary(results)}
    assert overall["hedged"].geomean_ratio == pytest.approx(math.sqrt(2.0)) and overall["hedged"].worse_than_random == 1
    assert overall["ranked"].geomean_ratio == pytest.approx(math.sqrt(3.0)) and overall["hedged"].default


def test_the_families_count_the_resolutions_of_the_model_side(table: ResultsTable) -> None:
    """Family a's hedged episodes: the model side chose the last trial in variants 0 and 3,
    random order in 1 and 2, and variant 4 names no side (a refused candidate tried last);
    family b's are from before the trace was kept. The ranking alone has no sides."""
    sides = {0: "model", 1: "random", 2: "random", 3: "model", 4: ""}
    hedged = [replace(r, resolving_pick=sides[r.variant] if r.scenario == "scenario1" else "") for r in _hedged(table)]
    results = {(r.ordering, r.family): r for r in family_results(ResultsTable([*table, *hedged]))}
    a, b = results[("hedged", "scenario1")], results[("hedged", "scenario2")]
    assert (a.resolved_by_model, a.resolved_with_pick) == (2, 4)
    assert (b.resolved_by_model, b.resolved_with_pick) == (0, 0)
    assert all(r.resolved_with_pick == 0 for (ordering, _), r in results.items() if ordering == "ranked")
    from llcps.report.formatting import model_side_share

    assert (model_side_share(2, 4), model_side_share(0, 0)) == ("2 of 4", "-")


@pytest.mark.parametrize("pick", ["x" * 17, "mo\tdel"])
def test_a_bad_resolving_pick_is_a_clean_error_naming_the_column(tmp_path: Path, pick: object) -> None:
    row = {**asdict(_row(DEFAULT[0], "scenario1", 0, 3)), "resolving_pick": pick}
    path = tmp_path / "results.json"
    path.write_text(json.dumps([row]))
    with pytest.raises(LlcpsError, match="column 'resolving_pick'"):
        ResultsTable.read(path)


def test_random_rows_of_the_papers_ordering_are_every_orderings_baseline(table: ResultsTable) -> None:
    hedged = _hedged(table)
    # The hedged store's own random rows (other numbers): the ranked ones still pair with hedged.
    own = [replace(r, ordering="hedged", exploration_trials=r.exploration_trials + 100) for r in table if r.model == "random"]
    results = family_results(ResultsTable([*table, *hedged, *own]))
    assert [r.median_ratio for r in results if r.ordering == "hedged"] == [2.0, 1.0]
    # Without random rows of the paper's ordering, an ordering pairs with its own.
    alone = family_results(ResultsTable([*hedged, *own]))
    assert [r.ordering for r in alone] == ["hedged", "hedged"] and alone[0].median_random == 104.0


def test_ratio_and_geometric_mean_edge_cases() -> None:
    assert ratio(0, 0) == 1.0 and ratio(3, 0) == math.inf and ratio(3, 6) == 0.5
    assert geometric_mean([0.5, 2.0]) == pytest.approx(1.0)
    assert math.isnan(geometric_mean([]))
    assert geometric_mean([math.inf, 2.0]) == math.inf


def test_others_rows_pair_with_random_under_others_only(table: ResultsTable) -> None:
    others = ResultsTable(replace(r, condition="others", branch=r.branch.replace("-reset-", "-others-")) for r in table)
    both = family_results(ResultsTable([*table, *others]))
    assert sorted({r.condition for r in both}) == ["others", "reset"] and len(both) == 4


def test_the_report_writes_the_family_table_json_and_plot(table: ResultsTable, tmp_path: Path) -> None:
    from llcps.report.build import build_report

    paths = build_report(table, tmp_path / "r", resamples=200, html=True)
    data = json.loads(paths.generalization_json.read_text())  # type: ignore[union-attr]
    assert [r["family"] for r in data["families"]] == ["scenario1", "scenario2"]
    assert data["headline_ratio"] == "median of per-variant ratios"
    assert data["overall"][0]["worse_than_random"] == 1
    text = paths.report_md.read_text()
    assert "## Leave one family out" in text and "| scenario2 |" in text
    assert {p.suffix for p in paths.plots["generalization"]} == {".png", ".svg"}
    assert 'id="generalization-1"' in paths.report_html.read_text()  # type: ignore[union-attr]
    # One ranked run reads as before orderings were recorded: its labels do not name the ordering.
    label = f"{DEFAULT[0]} / {DEFAULT[1]} / p200 / reset"  # the paper's ordering, not the default one
    assert f"| scenario1 | {label} |" in text and "ranked" not in text.split("## Leave one family out")[1]
    assert "Orderings:" not in text


def test_a_report_of_two_orderings_names_them_in_every_row_group(table: ResultsTable, tmp_path: Path) -> None:
    from llcps.report.build import build_report
    from llcps.report import plots

    drawn: list[list[str]] = []
    original = plots.save

    def save(fig, stem):  # noqa: ANN001, ANN202
        drawn.append([t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()])
        return original(fig, stem)

    both = ResultsTable([*table, *_hedged(table)])
    plots.save = save  # type: ignore[assignment]
    try:
        paths = build_report(both, tmp_path / "r", resamples=200, html=True)
    finally:
        plots.save = original  # type: ignore[assignment]
    model, measure = DEFAULT
    text = paths.report_md.read_text()
    assert f"| scenario1 | {model} / {measure} / ranked / p200 / reset | 5 |" in text
    assert f"| scenario1 | {model} / {measure} / hedged / p200 / reset (default) | 5 | 1 | 8.0 | 4.0 | 2.00 | 2.00 |" in text
    assert f"| {model} / {measure} / hedged / p200 / reset (default) | 2 | 1.41 | 1 of 2 |" in text
    assert "Orderings: ranked, hedged;" in text and "every other section covers the ranked ordering" in text
    assert f"{model} / {measure} / hedged / p200 / reset" in paths.report_html.read_text()  # type: ignore[union-attr]
    # The per-family plot draws one series per ordering (two markers each), the default's first
    legend = next(texts for texts in drawn if any("median of ratios" in t for t in texts))
    assert legend == [
        f"{model} / {measure} / {o} / p200 / reset: {what}" for o in ("hedged", "ranked") for what in ("median of ratios", "ratio of medians")
    ]
    rows = (tmp_path / "r" / "generalization.csv").read_text().splitlines()
    assert rows[0].split(",")[:5] == ["family", "model", "measure", "ordering", "pretrain_size"]
    data = json.loads(paths.generalization_json.read_text())  # type: ignore[union-attr]
    assert [(r["ordering"], r["label"]) for r in data["overall"]] == [
        ("hedged", f"{model} / {measure} / hedged / p200 / reset"), ("ranked", f"{model} / {measure} / ranked / p200 / reset")
    ]  # fmt: skip
    # Every other section covers one ordering: the random comparison holds the ranked rows only.
    analysis = json.loads(paths.figure2_json.read_text())
    assert analysis["overview"]["orderings"] == ["ranked", "hedged"] and analysis["overview"]["cell_ordering"] == "ranked"
    ranked_a = next(r for r in analysis["random_comparison"] if r["scenario"] == "scenario1")
    assert (ranked_a["n_model"], ranked_a["median_model"]) == (5, 6.0)
    assert ResultsTable.read(paths.results_csv) == both  # the report's results hold both orderings


# -- several results directories in one report ----------------------------------------------
def _results_dir(path: Path, rows: list[ResultRow], host: str) -> Path:
    ResultsTable(rows).write_csv(path / "results.csv")
    (path / "provenance.json").write_text(json.dumps([{"host": host, "llcps_version": "0.1.0", "runs": len(rows)}]))
    return path


def test_experiment_report_merges_the_results_of_two_orderings_into_one_report(table: ResultsTable, tmp_path: Path) -> None:
    random = [r for r in table if r.model == "random"]
    ranked = _results_dir(tmp_path / "ranked", list(table), "first")
    hedged = _results_dir(tmp_path / "hedged", [*random, *_hedged(table)], "second")  # a copy of the store's random rows
    out = tmp_path / "orderings"
    runner = CliRunner()
    result = runner.invoke(app, ["experiment", "report", str(ranked), str(hedged / "results.csv"), "--out-dir", str(out), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert [(r["ordering"], r["family"], r["median_ratio"]) for r in data["generalization"]["families"]] == [
        ("hedged", "scenario1", 2.0), ("hedged", "scenario2", 1.0), ("ranked", "scenario1", 1.0), ("ranked", "scenario2", 3.0),
    ]  # fmt: skip
    merged = ResultsTable.read(out)
    assert len(merged) == len(table) + len(table) // 2 and merged.unique("ordering") == ("ranked", "hedged")
    text = (out / "report.md").read_text()
    model, measure = DEFAULT
    assert f"| scenario1 | {model} / {measure} / hedged / p200 / reset (default) | 5 | 1 | 8.0 | 4.0 | 2.00 |" in text
    assert f"| scenario1 | {model} / {measure} / ranked / p200 / reset | 5 | 1 | 6.0 | 4.0 | 1.00 |" in text
    # where the runs ran: every directory's environments, each marked with its directory
    provenance = json.loads((out / "provenance.json").read_text())
    assert sorted((p["host"], p["results"]) for p in provenance) == [("first", str(ranked)), ("second", str(hedged))]
    assert f"[{hedged}]" in text
    shown = runner.invoke(app, ["experiment", "report", str(ranked), str(hedged), "--out-dir", str(tmp_path / "again")])
    assert shown.exit_code == 0 and f"{model} / {measure} / hedged / p200 / reset" in shown.stdout
    # ... and the merged directory reports alone, its provenance still marked
    alone = runner.invoke(app, ["experiment", "report", str(out), "--out-dir", str(tmp_path / "alone"), "--json"])
    assert alone.exit_code == 0 and json.loads((tmp_path / "alone" / "provenance.json").read_text()) == provenance


def test_experiment_report_of_several_directories_refuses_conflicts_and_wants_an_out_dir(table: ResultsTable, tmp_path: Path) -> None:
    random = [r for r in table if r.model == "random"]
    ranked = _results_dir(tmp_path / "ranked", list(table), "first")
    # a hedged run's results written before the ordering was recorded: they read as ranked
    old = _results_dir(tmp_path / "old", [*random, *(replace(r, ordering="ranked") for r in _hedged(table))], "second")
    runner = CliRunner()
    clash = runner.invoke(app, ["experiment", "report", str(ranked), str(old), "--out-dir", str(tmp_path / "out")])
    assert clash.exit_code == 2, clash.output
    first = min((r for r in table if r.model != "random"), key=lambda r: (r.sequence, scenario_rank(r.scenario)))
    assert f"{ranked} and {old} hold different results for {first.branch} {first.scenario} (ranked)" in clash.stderr
    assert "ordering column" in clash.stderr and "Traceback" not in clash.output and not (tmp_path / "out").exists()
    bare = runner.invoke(app, ["experiment", "report", str(ranked), str(old)])
    assert bare.exit_code == 2 and "needs its own directory" in bare.stderr and "--out-dir" in bare.stderr
    assert "Traceback" not in bare.output and not (ranked / "report.md").exists()


# -- a tiny grid end to end ------------------------------------------------------------------
TINY = replace(PRESETS["generalization"], budget=5, pretrain_pool=8, pretrain_sizes=(8,), scenarios=("scenario1", "scenario4"))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Store, Path, object]]:
    out = tmp_path_factory.mktemp("gen")
    with Store.open(str(out / "g.db"), create=True) as store:
        result = run_experiment_job(store=store, preset=TINY, variants=range(0, 2), workers=1, out_dir=out / "report")
        yield store, out, result


def test_a_tiny_generalization_grid_reports_every_family(tiny: tuple[Store, Path, object]) -> None:
    store, out, result = tiny
    assert result.summary.status == "ok"  # type: ignore[attr-defined]
    table = table_from_episodes(store.list_episodes()).table
    assert {(r.scenario, r.model, r.variant, r.draw) for r in table} == {
        (f, m, v, d) for f in ("scenario1", "scenario4") for m in (DEFAULT[0], "random") for v in (0, 1) for d in range(3 if m == "random" else 1)
    }  # fmt: skip
    assert all(r.condition == "reset" for r in table)
    # The default (hedged) says which side resolved each episode; the random order has no sides.
    hedged = [r for r in table if r.model == DEFAULT[0]]
    assert {r.ordering for r in hedged} == {"hedged"} and all(r.resolving_pick == "" for r in table if r.model == "random")
    assert all(r.resolving_pick in ("model", "random") for r in hedged if r.solved and r.exploration_trials)
    families = result.analysis["generalization"]["families"]  # type: ignore[attr-defined]
    default = [r for r in families if r["default"]]
    assert sum(r["resolved_with_pick"] for r in default) == sum(1 for r in hedged if r.resolving_pick)
    assert sum(r["resolved_by_model"] for r in default) == sum(1 for r in hedged if r.resolving_pick == "model")
    assert [r["family"] for r in families] == ["scenario1", "scenario4"] and all(r["n"] == 2 and r["random_draws"] == 3 for r in families)
    # Each draw of the random order explored with a world model seeded apart: three permutations per variant.
    random = [e for e in store.list_episodes() if e.summary.get("model") == "random"]
    seeds = {(e.branch, store.get_run(e.run_id).config["model_seed"]) for e in random}  # type: ignore[arg-type]
    assert len(seeds) == 2 * 2 * 3 and len({s for _, s in seeds}) == 2 * 3
    assert "## Leave one family out" in (out / "report" / "report.md").read_text()
    assert (out / "report" / "generalization.csv").is_file()
    # The pretraining of each seed holds every family out: no trial of it starts from their scenes.
    for seed in (0, 1):
        branch = f"exp-generalization-pretrain-p8-s{seed}"
        assert len(store.visible_trials(branch)) == 8
        assert pretraining_leaks(store, branch, ["scenario1", "scenario4"], variants=(0, 1)) == ()
    # ... and the check would see a leak: an episode's branch holds the scenario's own trials.
    episode_branch = next(r.branch for r in table if r.model == DEFAULT[0])
    assert pretraining_leaks(store, episode_branch, ["scenario1"], variants=(0, 1))


def test_a_rerun_skips_every_stored_task(tiny: tuple[Store, Path, object]) -> None:
    store = tiny[0]
    again = run_experiment_job(store=store, preset=TINY, variants=range(0, 2), workers=1, out_dir=tiny[1] / "again")
    assert again.summary.skipped == again.summary.tasks and again.summary.done == 0


def test_with_others_solves_the_other_families_first_and_a_new_list_is_refused(tiny: tuple[Store, Path, object]) -> None:
    store, out, _ = tiny
    result = run_experiment_job(store=store, preset=TINY, variants=range(0, 1), with_others=True, workers=1, out_dir=out / "others")
    assert result.summary.status == "ok"
    branch = f"exp-generalization-{DEFAULT[0]}-{DEFAULT[1]}-p8-others-s0-scenario4"
    assert [e.scenario for e in sorted(store.list_episodes(branch=branch), key=lambda e: e.id)] == ["scenario1", "scenario4"]
    rows = [r for r in table_from_episodes(store.list_episodes()).table if r.condition == "others"]
    models = (DEFAULT[0],) + ("random",) * TINY.random_draws  # the random order in each of its draws
    assert sorted((r.scenario, r.model) for r in rows) == sorted((f, m) for f in ("scenario1", "scenario4") for m in models)
    families = result.analysis["generalization"]["families"]  # type: ignore[index]
    assert {(r["family"], r["condition"]) for r in families} >= {("scenario1", "others"), ("scenario4", "others")}
    # The same branch names over another list would pass for its results: refused before anything runs.
    with pytest.raises(LlcpsError, match="holds episodes of scenario4, scenario1, not of scenario1 as this run asks"):
        run_experiment_job(store=store, preset=TINY, scenarios=["scenario1"], variants=range(0, 1), with_others=True, out_dir=out / "x")
