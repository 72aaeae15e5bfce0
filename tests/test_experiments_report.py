"""The experiment data flow: grid and branch names, the results table, and the written report."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from llcps.errors import LlcpsError
from llcps.experiments import design, presets
from llcps.experiments.design import PAPER_SCENARIOS, Cell, Sequence, parse_branch
from llcps.experiments.presets import PRESETS, Preset
from llcps.analysis.analyse import analyse, report_json
from llcps.report.build import build_report
from llcps.report.text import summary_lines
from llcps.analysis.results import ResultsTable, table_from_episodes
from llcps.experiments.rows import COLUMNS, ResultRow

# -- grid ----------------------------------------------------------------------------------

EXPECTED_SIZES = {
    "paper": (2 * 4 * 2 * 2, 20),
    "full": (5 * 5 * 2 * 2, 20),
    "smoke": (2, 2),
    "vs_random": (2, 20),
    "lifelong": (2, 20),
    "models": (5, 5),
    "random": (1, 20),
    "generalization": (2, 10),
}


def test_every_preset_has_a_documented_size() -> None:
    assert set(PRESETS) == set(EXPECTED_SIZES)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_size_and_default_seeds(name: str) -> None:
    preset = PRESETS[name]
    cells, seeds = EXPECTED_SIZES[name]
    assert len(preset.cells()) == len(set(preset.cells())) == cells
    # per seed, one sequence per cell and one more per further draw of the random order
    per_seed = cells + sum(preset.random_draws - 1 for c in preset.cells() if c.model == "random")
    assert len(preset.sequences()) == per_seed * seeds
    assert len(preset.sequences(3)) == per_seed * 3
    assert {s.seed for s in preset.sequences([5, 9])} == {5, 9}


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_branch_names_are_valid_unique_and_parse_back(name: str) -> None:
    sequences = PRESETS[name].sequences(3)
    names = [s.branch_name for s in sequences]
    assert len(set(names)) == len(names)
    episode_branches: set[str] = set()
    for seq in sequences:
        assert design.is_valid_branch_name(seq.branch_name) and "/" not in seq.branch_name
        assert parse_branch(seq.branch_name) == design.ParsedBranch(seq, None)
        for scenario in PAPER_SCENARIOS:
            branch = seq.episode_branch(scenario)
            assert design.is_valid_branch_name(branch)
            parsed = parse_branch(branch)
            assert parsed is not None and parsed.sequence == seq
            assert parsed.scenario == (scenario if seq.cell.condition == "reset" else None)
            episode_branches.add(branch)
        assert parse_branch(seq.pretrain_branch) is None
    # Update sequences share one branch across scenarios, reset sequences get one per scenario.
    n_update = sum(s.cell.condition == "update" for s in sequences)
    assert len(episode_branches) == n_update + 3 * (len(sequences) - n_update)


def test_pretraining_branch_is_shared_by_models_and_conditions() -> None:
    a = Sequence("paper", Cell("nn", "most-changes", 4, "update"), 3)
    b = Sequence("paper", Cell("nb", "least-destructive", 4, "reset"), 3)
    assert a.pretrain_branch == b.pretrain_branch
    assert a.pretrain_branch != Sequence("paper", Cell("nn", "most-changes", 200, "update"), 3).pretrain_branch


@pytest.mark.parametrize(
    "name",
    ["main", "exp-paper", "exp-paper-nb-most-changes-p200-maybe-s3", "exp-paper-nb-most-changes-p200-update-s03",
     "exp-paper-nb-most-changes-p200-update-s3-scenario2", "exp-paper-nb-most-changes-p200-reset-s3-9lives",
     "exp-paper-pretrain-p200-s3", "exp-paper-nb--p200-update-s3"],
)  # fmt: skip
def test_other_branch_names_do_not_parse(name: str) -> None:
    assert parse_branch(name) is None


def test_measures_with_separators_parse_back() -> None:
    seq = Sequence("full", Cell("logreg", "least-negative-changes", 200, "reset"), 12)
    assert parse_branch(seq.episode_branch("scenario3")) == design.ParsedBranch(seq, "scenario3")


@pytest.mark.parametrize(
    "make",
    [
        lambda: Cell("n-n", "most-changes", 4, "update"),
        lambda: Cell("nb", "Most Changes", 4, "update"),
        lambda: Cell("nb", "most-changes", -1, "update"),
        lambda: Cell("nb", "most-changes", 4, "sometimes"),
        lambda: Sequence("pa-per", Cell("nb", "most-changes", 4, "update"), 0),
        lambda: Sequence("paper", Cell("nb", "most-changes", 4, "update"), -2),
        lambda: Sequence("paper", Cell("nb", "m" * 80, 4, "reset"), 0),
        lambda: PRESETS["paper"].sequences(0),
        lambda: presets.get_preset("huge"),
    ],
)
def test_bad_grid_input_is_a_project_error(make) -> None:  # noqa: ANN001
    with pytest.raises(LlcpsError):
        make()


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_names_exist_in_the_registries(name: str) -> None:
    try:
        from llcps.models import WORLD_MODELS  # noqa: F401
        from llcps.models.measures import MEASURES  # noqa: F401
    except ImportError as exc:  # the registries arrive with the world models
        pytest.skip(f"model registries not importable yet: {exc}")
    presets.validate_preset(PRESETS[name])


# -- results table -------------------------------------------------------------------------

TEST_PRESET = Preset(
    "test",
    models=("nn", "nb", "random"),
    measures=("least-destructive", "most-changes"),
    pretrain_sizes=(200, 4),
    default_seeds=4,
)


def synthetic_table(seeds: int = 4, rng_seed: int = 0) -> ResultsTable:
    """Exploration that updates cut by about a third in scenarios 2 and 3; scenario 1 equal."""
    rng = np.random.default_rng(rng_seed)
    rows = []
    for seq in TEST_PRESET.sequences(seeds):
        for i, scenario in enumerate(PAPER_SCENARIOS):
            if i == 0:  # the control: identical under both conditions
                trials = 10 + seq.seed
            else:
                base = 30.0 if seq.cell.model == "random" else 20.0 + 5 * i
                trials = int(rng.poisson(base * (0.65 if seq.cell.condition == "update" else 1.0)))
            rows.append(
                ResultRow(
                    preset=seq.preset,
                    model=seq.cell.model,
                    measure=seq.cell.measure,
                    pretrain_size=seq.cell.pretrain_size,
                    condition=seq.cell.condition,
                    seed=seq.seed,
                    scenario=scenario,
                    solved=trials < 40,
                    exploration_trials=trials,
                    sim_seconds=0.05 * trials,
                    wall_seconds=0.1 * trials + 0.5,
                    episode_id=len(rows) + 1,
                    branch=seq.episode_branch(scenario),
                )
            )
    return ResultsTable(rows)


def test_csv_and_json_round_trip(tmp_path) -> None:  # noqa: ANN001
    table = synthetic_table(seeds=2)
    assert ResultsTable.read(table.write_csv(tmp_path / "r.csv")) == table
    assert ResultsTable.read(table.write_json(tmp_path / "r.json")) == table
    assert ResultsTable.read(tmp_path / "r.csv").rows[0].episode_id == table.rows[0].episode_id
    header = (tmp_path / "r.csv").read_text().splitlines()[0]
    assert header.split(",") == list(COLUMNS)


def test_bad_results_file_is_a_project_error(tmp_path) -> None:  # noqa: ANN001
    path = synthetic_table(seeds=1).write_csv(tmp_path / "r.csv")
    text = path.read_text().splitlines()
    text[1] = text[1].replace(",true,", ",perhaps,").replace(",false,", ",perhaps,")  # booleans are written true/false
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(LlcpsError, match="solved"):
        ResultsTable.read_csv(path)
    with pytest.raises(LlcpsError):
        ResultsTable.read_csv(tmp_path / "missing.csv")


def test_results_written_before_the_ordering_column_read_as_the_papers_ordering(tmp_path) -> None:  # noqa: ANN001
    table = synthetic_table(seeds=1)
    hedged = ResultsTable(dataclasses.replace(r, ordering="hedged", resolving_pick="model") for r in table)
    assert ResultsTable.read(hedged.write_csv(tmp_path / "h.csv")) == hedged  # the columns round-trip
    lines = table.write_csv(tmp_path / "r.csv").read_text().splitlines()
    assert lines[0].endswith(",ordering,draw,resolving_pick") and all(line.endswith(",ranked,0,") for line in lines[1:])
    (tmp_path / "old.csv").write_text("\n".join(line.rsplit(",", 3)[0] for line in lines) + "\n")
    assert not {"ordering", "draw", "resolving_pick"} & set((tmp_path / "old.csv").read_text().splitlines()[0].split(","))
    old = ResultsTable.read(tmp_path / "old.csv")
    assert old == table and old.unique("ordering") == ("ranked",) and old.unique("draw") == (0,) and old.unique("resolving_pick") == ("",)
    drawn = ResultsTable(dataclasses.replace(r, draw=2) for r in table)
    assert ResultsTable.read(drawn.write_csv(tmp_path / "d.csv")) == drawn  # the draw column round-trips
    records = json.loads(hedged.write_json(tmp_path / "h.json").read_text())
    for record in records["rows"]:
        del record["ordering"]
    (tmp_path / "old.json").write_text(json.dumps(records))
    assert ResultsTable.read(tmp_path / "old.json").unique("ordering") == ("ranked",)
    for bad in ("", "two\nlines"):
        with pytest.raises(ValueError, match="ordering"):
            dataclasses.replace(table.rows[0], ordering=bad)


def test_rows_of_two_orderings_of_one_sequence_and_scenario_sit_in_one_table() -> None:
    table = synthetic_table(seeds=1)
    hedged = [dataclasses.replace(r, ordering="hedged", exploration_trials=r.exploration_trials + 1) for r in table]
    both = ResultsTable([*hedged, *table])
    assert len(both) == 2 * len(table) and both.unique("ordering") == ("ranked", "hedged")
    assert both.rows[0].key == (both.rows[0].sequence, both.rows[0].scenario, "ranked")
    assert both.filter(ordering="hedged") == ResultsTable(hedged)
    assert both.complete_sequences() == table.complete_sequences()
    # one ordering incomplete: the sequence is not complete, though the other ordering's rows are
    partial = ResultsTable(r for r in both if not (r.ordering == "hedged" and r.scenario == "scenario3" and r.seed == 0))
    assert partial.complete_runs() < both.complete_runs()
    assert not any(s.seed == 0 for s in partial.complete_sequences())
    with pytest.raises(LlcpsError, match=r"two results for .* scenario1 \(hedged\)"):
        ResultsTable([hedged[0], dataclasses.replace(hedged[0], exploration_trials=99)])


def test_merging_tables_keeps_rows_held_alike_once_and_refuses_different_ones() -> None:
    from llcps.analysis.results import merge_tables

    table = synthetic_table(seeds=1)
    random = ResultsTable(r for r in table if r.model == "random")
    hedged = ResultsTable([*random, *(dataclasses.replace(r, ordering="hedged") for r in table if r.model != "random")])
    merged = merge_tables([("a/results.csv", table), ("b/results.csv", hedged)])
    assert len(merged) == len(table) + len(hedged) - len(random)
    assert merged.filter(ordering="hedged") == hedged.filter(ordering="hedged")
    changed = next(r for r in table if r.model == "nb")
    other = ResultsTable([dataclasses.replace(changed, exploration_trials=changed.exploration_trials + 1)])
    with pytest.raises(LlcpsError) as info:
        merge_tables([("a/results.csv", table), ("b/results.csv", other)])
    assert f"a/results.csv and b/results.csv hold different results for {changed.branch} {changed.scenario} (ranked)" in info.value.message
    assert "ordering column" in (info.value.hint or "")


def _summary(seq: Sequence, scenario: str, trials: int, episode_id: int, **extra: object) -> dict[str, object]:
    """The shape of ``SolveResult.as_json()`` as the store keeps it."""
    return {
        "scenario": scenario,
        "condition": "novelty",
        "model": seq.cell.model,
        "measure": seq.cell.measure,
        "seed": seq.seed,
        "branch": seq.episode_branch(scenario),
        "solved": True,
        "status": "solved",
        "exploration_trials": trials,
        "sim_seconds": 1.5,
        "wall_seconds": 2.25,
        "episode_id": episode_id,
        **extra,
    }


def test_table_from_episodes_parses_branches_and_keeps_the_latest() -> None:
    update, reset = PRESETS["smoke"].sequences(1)
    episodes = [_summary(update, s, 10 + i, i + 1) for i, s in enumerate(PAPER_SCENARIOS)]
    episodes += [_summary(reset, s, 20 + i, 10 + i) for i, s in enumerate(PAPER_SCENARIOS)]
    episodes += [
        _summary(reset, "scenario2", 99, 5),  # an older attempt at the same scenario
        _summary(update, "scenario3", 7, 50, status="running"),  # cut off mid-episode
        {**_summary(update, "scenario1", 1, 60), "branch": "main"},  # someone's own branch
        _summary(update, "scenario1", 1, 61, condition="original"),
    ]
    imported = table_from_episodes(episodes)
    table = imported.table
    assert len(table) == 6
    assert table.complete_sequences() == {update, reset}
    assert table.unique("ordering") == ("ranked",)  # summaries written before the ordering was recorded
    row = next(r for r in table if r.condition == "reset" and r.scenario == "scenario2")
    assert (row.exploration_trials, row.episode_id, row.preset, row.pretrain_size) == (21, 11, "smoke", 4)
    assert imported.skipped == {
        "superseded by a later episode": 1,
        "unfinished episode": 1,
        "not an experiment branch": 1,
        "not the novelty condition": 1,
    }


def test_table_from_episodes_takes_the_ordering_from_each_summary() -> None:
    update, _ = PRESETS["smoke"].sequences(1)
    episodes = [_summary(update, s, 10 + i, i + 1, ordering="trial-and-error") for i, s in enumerate(PAPER_SCENARIOS)]
    episodes.append(_summary(update, "scenario1", 4, 9, ordering="hedged"))  # another ordering on the same branch
    table = table_from_episodes(episodes).table
    assert sorted((r.scenario, r.ordering) for r in table) == sorted(
        [(s, "trial-and-error") for s in PAPER_SCENARIOS] + [("scenario1", "hedged")]
    )


def test_table_from_a_real_store(tmp_path) -> None:  # noqa: ANN001
    from llcps.store import Store

    store = Store.open(str(tmp_path / "exp.db"), create=True)
    store.init()
    try:
        update, reset = PRESETS["smoke"].sequences(1)
        expected = {}
        for seq in (update, reset):
            for i, scenario in enumerate(PAPER_SCENARIOS):
                branch = seq.episode_branch(scenario)
                if branch not in {b.name for b in store.list_branches()}:
                    store.create_branch(branch, from_branch="main", at="pretrain")
                cell = seq.cell
                episode = store.start_episode(
                    run_id=None, branch=branch, scenario=scenario, condition="novelty",
                    model=cell.model, measure=cell.measure, seed=seq.seed,
                )  # fmt: skip
                if seq is update and scenario == "scenario3":
                    continue  # killed mid-episode: stays "running" with an empty summary
                trials = 3 * i + (cell.condition == "reset")
                store.finish_episode(episode, status="solved", summary=_summary(seq, scenario, trials, episode))
                expected[(cell.condition, scenario)] = (trials, episode)
        imported = table_from_episodes(store.list_episodes())
    finally:
        store.close()
    assert imported.skipped == {"unfinished episode": 1}
    assert {(r.condition, r.scenario): (r.exploration_trials, r.episode_id) for r in imported.table} == expected
    assert imported.table.missing(PRESETS["smoke"].sequences(1)) == (update,)


def test_missing_lists_incomplete_sequences_in_order() -> None:
    table = synthetic_table(seeds=2)
    partial = ResultsTable(r for r in table if not (r.seed == 1 and r.scenario == "scenario3"))
    wanted = TEST_PRESET.sequences(3)
    missing = partial.missing(wanted)
    assert missing == tuple(s for s in wanted if s.seed in (1, 2))


# -- report --------------------------------------------------------------------------------


def _strict_json(text: str) -> object:
    def refuse(name: str) -> None:
        raise ValueError(f"non-standard JSON constant {name}")

    return json.loads(text, parse_constant=refuse)


def test_build_report_writes_every_file(tmp_path) -> None:  # noqa: ANN001
    table = synthetic_table()
    paths = build_report(table, tmp_path / "report", resamples=1000, seed=0)
    for path in paths.all():
        assert path.is_file() and path.stat().st_size > 0, path
    scenarios = {f"survival_{s}" for s in PAPER_SCENARIOS}
    assert set(paths.plots) == {"figure2", "distribution", "cumulative", *scenarios}
    assert paths.survival_csv is not None and all(f"plots/{name}.png" in paths.report_md.read_text() for name in scenarios)
    assert {p.suffix for ps in paths.plots.values() for p in ps} == {".png", ".svg"}
    assert paths.random_csv is not None
    assert ResultsTable.read(paths.results_csv) == table

    data = _strict_json(paths.figure2_json.read_text())
    assert data == report_json(table, resamples=1000, seed=0)
    figure2 = data["figure2"]
    # 2 non-random models... and random too: 3 models x 2 measures x 2 sizes x 3 scenarios.
    assert len(figure2) == 3 * 2 * 2 * 3
    nb = next(
        r
        for r in figure2
        if (r["model"], r["measure"], r["pretrain_size"], r["scenario"]) == ("nb", "most-changes", 4, "scenario2")
    )
    assert nb["paper_pct_change"] == 640.0 and nb["n_seeds"] == 4
    assert nb["ci_low"] <= nb["pct_change"] <= nb["ci_high"]
    control = [r for r in figure2 if r["scenario"] == "scenario1"]
    assert all(r["pct_change"] == 0 and r["p_value"] is None and "zero" in r["p_reason"] for r in control)

    md = paths.report_md.read_text()
    row = next(
        r
        for r in figure2
        if (r["model"], r["measure"], r["pretrain_size"], r["scenario"])
        == ("nn", "least-destructive", 200, "scenario2")
    )
    from llcps.report.formatting import format_pct

    assert f"| nn | least-destructive | {format_pct(row['pct_change'])}" in md
    assert "| +182% |" in md  # the paper's NN / least destructive / scenario 2 with 200 points
    assert "| 4 | all | 16 |" not in md and "| 4 | all | 12 |" in md  # 3 models x 2 measures x 2 scenarios
    assert "![Figure 2 heatmap](plots/figure2.png)" in md
    assert "## Model-guided vs random order" in md
    assert "are identical seed by seed" in md


@pytest.mark.slow
def test_report_is_reproducible(tmp_path) -> None:  # noqa: ANN001
    table = synthetic_table(seeds=3)
    first = build_report(table, tmp_path / "a", resamples=500, seed=4)
    second = build_report(table, tmp_path / "b", resamples=500, seed=4)
    for a, b in zip(first.all(), second.all()):
        if a.suffix != ".png":
            assert a.read_bytes() == b.read_bytes(), a.name


def test_report_of_nothing_is_a_project_error(tmp_path) -> None:  # noqa: ANN001
    with pytest.raises(LlcpsError, match="empty"):
        build_report(ResultsTable(), tmp_path)


def test_report_json_of_a_table_without_pairs_has_no_figure2_rows() -> None:
    table = synthetic_table(seeds=2).filter(condition="update")
    data = report_json(table, resamples=200)
    assert data["figure2"] == [] and data["reduction"]["ours"] == []
    assert all(not isinstance(v, float) or math.isfinite(v) for v in data["overview"].values())


def test_a_report_of_one_condition_draws_no_empty_figure2(tmp_path) -> None:  # noqa: ANN001
    """A reset-only table (the vs_random preset's shape) has no Figure 2: the page says so and
    keeps the comparison with the random order; no empty heatmap is drawn."""
    paths = build_report(synthetic_table(seeds=3).filter(condition="reset"), tmp_path, resamples=200)
    md = paths.report_md.read_text()
    assert "## Figure 2" not in md and "## How often updating reduced" not in md
    assert "pair no `update` sequence with a `reset` one" in md
    assert "## Model-guided vs random order" in md
    assert "figure2" not in paths.plots and not (tmp_path / "plots" / "figure2.png").exists()


def test_a_report_over_scene_variants_names_them_and_tabulates_each() -> None:
    from dataclasses import replace

    table = ResultsTable(
        replace(r, variant=r.seed, branch=replace(r.sequence, variant=r.seed).episode_branch(r.scenario))
        for r in synthetic_table(seeds=3)
    )
    data = report_json(table, resamples=200)
    assert data["overview"]["variants"] == [0, 1, 2]
    cells = {c.label for c in TEST_PRESET.cells()}
    assert "random order / p200 / reset" in cells  # the random order ignores the measure
    assert len(data["per_variant"]) == 3 * len(PAPER_SCENARIOS)
    for v in data["per_variant"]:
        assert v["seed"] == v["variant"] and set(v["results"]) == cells
        row = table.filter(scenario=v["scenario"], seed=v["seed"], model="nb", condition="update").rows[0]
        label = f"nb / {row.measure} / p{row.pretrain_size} / update"
        assert v["results"][label]["value"] == row.exploration_trials
    assert report_json(synthetic_table(seeds=3), resamples=200)["per_variant"] == []  # canonical scenes only


@pytest.fixture(scope="module")
def synthetic_analysis():  # noqa: ANN201
    return analyse(synthetic_table(seeds=4), resamples=200)


@pytest.mark.parametrize("holm_significant", [0, 1, 2])
def test_the_summary_counts_cells_surviving_holm_with_a_verb_that_agrees(synthetic_analysis, holm_significant: int) -> None:  # noqa: ANN001
    analysis = synthetic_analysis
    rows = [r for r in analysis.figure2 if r.scenario != PAPER_SCENARIOS[0]]
    assert len(rows) > holm_significant
    forced = {id(r) for r in rows[:holm_significant]}
    analysis = dataclasses.replace(
        analysis,
        figure2=tuple(dataclasses.replace(r, p_holm=0.001 if id(r) in forced else 1.0) for r in analysis.figure2),
    )
    line = next(line for line in summary_lines(analysis) if "after Holm's correction" in line and "Wilcoxon" in line)
    verb = "remains" if holm_significant == 1 else "remain"
    assert f"; {holm_significant} {verb} after Holm's correction" in line


def test_the_summary_counts_only_log_rank_tests_that_were_made(synthetic_analysis) -> None:  # noqa: ANN001
    analysis = synthetic_analysis
    untested = [r for r in analysis.survival if math.isnan(r.p_value)]
    assert untested and len(untested) < len(analysis.survival)  # the control scenario has none
    line = next(line for line in summary_lines(analysis) if "log-rank" in line)
    tested = len(analysis.survival) - len(untested)
    assert f"of {tested} tested cells differ" in line
    assert f"({len(untested)} more have no test" in line
