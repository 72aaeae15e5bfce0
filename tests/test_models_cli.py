"""``llcps inspect model`` on a real store: metrics beside the baseline, JSON shape,
errors for people, and a scenario's failure-state candidates ranked per measure."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.trial_records import TrialRecord
from llcps.models import MEASURES, PAPER_MODELS
from llcps.models.synthetic import synthetic_trials
from llcps.scenarios import SCENARIOS
from llcps.store import Store


@pytest.fixture
def db(tmp_path):
    path = str(tmp_path / "llcps.db")
    with Store.open(path, create=True) as store:
        store.add_trials(
            [
                TrialRecord(
                    branch="main",
                    source="pretrain",
                    spec=r.spec,
                    features=r.features,
                    outcome=r.outcome,
                    solved=False,
                    sim_steps=0,
                    wall_seconds=0.0,
                    seed=1,
                )
                for r in synthetic_trials(160, seed=1)
            ]
        )
    return path


def run(db, *args):
    return CliRunner().invoke(app, ["--db", db, "inspect", "model", *args])


def test_json_reports_the_paper_models_beside_the_baseline(db):
    result = run(db, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["n_trials"] == 160
    assert [e["model"] for e in data["evaluations"]] == list(PAPER_MODELS)
    for evaluation in data["evaluations"]:
        assert (evaluation["n_train"], evaluation["n_test"]) == (120, 40)
        assert {"f1", "baseline_f1", "brier", "baseline_brier", "accuracy"} <= set(evaluation["labels"][0])
    assert "scenario" not in data


def test_table_output_names_every_model(db):
    result = run(db, "--model", "logreg", "--model", "random")
    assert result.exit_code == 0, result.output
    assert "logreg:" in result.stdout and "random:" in result.stdout and "nb:" not in result.stdout


def test_too_few_trials_is_a_note_not_a_crash(tmp_path):
    path = str(tmp_path / "empty.db")
    Store.open(path, create=True).close()
    result = run(path, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["evaluations"] == [] and "at least 2 trials" in data["evaluation_note"]


def test_unknown_scenario_is_one_line_and_exit_2(db):
    result = run(db, "--scenario", "scenario99")
    assert result.exit_code == 2
    assert "unknown scenario" in result.output and "Traceback" not in result.output


def test_a_scenario_file_is_ranked_like_a_shipped_scenario(db, tmp_path):
    """A scenario given as a file is read from it (not looked up by the name inside it)."""
    path = tmp_path / "mine.toml"
    path.write_text(SCENARIOS["scenario2"].source.text.replace('name = "scenario2"', 'name = "mine"').replace('alias = "container"', ""))
    result = run(db, "--scenario", str(path), "--limit", "3", "--model", "nb", "--json")
    assert result.exit_code == 0, result.output
    ranked = json.loads(result.stdout)["scenario"]
    assert ranked["name"] == "mine" and ranked["candidates"] > 3


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_scenario_candidates_are_ranked_under_every_measure(db, scenario):
    result = run(db, "--scenario", scenario, "--limit", "4", "--model", "nb", "--json")
    assert result.exit_code == 0, result.output
    ranked = json.loads(result.stdout)["scenario"]
    assert ranked["name"] == scenario and ranked["candidates"] > 4
    orders = {measure: [c["trial"] for c in ranked["rankings"]["nb"][measure]] for measure in MEASURES}
    assert set(orders) == set(MEASURES) and all(len(o) == 4 for o in orders.values())
    # a model trained on trials with structure orders candidates differently per measure
    assert len({tuple(order) for order in orders.values()}) > 1


def test_inspect_shows_which_candidates_k_claims_and_their_lift(db):
    """K's push(?o ?c) and place_in_container(?o ?c) add (in ?o ?c): in scenario2 those
    candidates on the can claim the missing (in can bin), nothing else does, and every
    claimed candidate gets at least the novelty mix."""
    from llcps.models.goal import NOVELTY_MIX

    result = run(db, "--scenario", "scenario2", "--limit", "1000", "--model", "nb", "--json")
    assert result.exit_code == 0, result.output
    ranked = json.loads(result.stdout)["scenario"]["rankings"]["nb"]["goal-directed"]
    claimed = {c["trial"] for c in ranked if c["claimed"]}
    expected = {c["trial"] for c in ranked if c["trial"].startswith(("push(can)", "place_in_container(can, bin)"))}
    assert claimed == expected and len(expected) == 36 + 35  # the failed placement itself is no candidate
    assert all(c["claimed"] == ["+(in can bin)"] for c in ranked if c["claimed"])
    assert min(c["goal"]["+(in can bin)"] for c in ranked if c["claimed"]) >= NOVELTY_MIX - 1e-4


def test_inspect_shows_scenario2_s_subgoal_and_ranks_by_resolving(db):
    """With the bin out of reach, K's push(can, bin) would still put the can in it but
    lacks (near can bin): that is scenario 2's subgoal, and goal-directed ranks by the
    probability of resolving through either way, never below the missing atom's alone."""
    result = run(db, "--scenario", "scenario2", "--limit", "1000", "--model", "nb", "--json")
    assert result.exit_code == 0, result.output
    point = json.loads(result.stdout)["scenario"]
    assert point["subgoals"] == ["(push can bin) needs +(near can bin)"]
    ranked = point["rankings"]["nb"]["goal-directed"]
    assert all(set(c["subgoals"]) == set(point["subgoals"]) for c in ranked)
    assert all(c["resolve"] >= c["joint"] - 1e-6 for c in ranked)
    resolve = [c["resolve"] for c in ranked if not c["refused"]]
    assert resolve == sorted(resolve, reverse=True)  # the order is by P(resolve), ties aside, refused calls last
    assert any(c["resolve"] > c["joint"] + 1e-3 for c in ranked)  # the subgoal counts


def test_inspect_lists_last_what_the_arm_would_refuse_as_the_agent_tries_it(db):
    """In scenario2 the bin stands beyond the arm's top-down reach: every placement into it
    and removal from it is refused. The reach check lists those after every other candidate, in candidate
    order, as `llcps solve` tries them; without it, the measure's order alone."""
    on = json.loads(run(db, "--scenario", "scenario2", "--limit", "1000", "--model", "nb", "--json").stdout)["scenario"]
    off = json.loads(run(db, "--scenario", "scenario2", "--limit", "1000", "--model", "nb", "--no-reach-check", "--json").stdout)["scenario"]
    assert off["refused"] == 0 and not any(c["refused"] for c in off["rankings"]["nb"]["goal-directed"])
    ranked = on["rankings"]["nb"]["goal-directed"]
    refused = [c for c in ranked if c["refused"]]
    assert len(refused) == on["refused"] > 0 and ranked[-len(refused) :] == refused
    assert all(c["trial"].startswith(("place_in_container(", "remove_from_container(")) and ", bin)" in c["trial"] for c in refused)
    tried_first = [c["trial"] for c in off["rankings"]["nb"]["goal-directed"] if c["trial"] not in {r["trial"] for r in refused}]
    assert [c["trial"] for c in ranked[: -len(refused)]] == tried_first  # the rest keep the measure's order
    assert [c["position"] for c in ranked] == list(range(1, len(ranked) + 1))
    text = run(db, "--scenario", "scenario2", "--limit", "3", "--model", "nb")
    assert f"{on['refused']} the arm would refuse here (tried last)" in " ".join(text.output.split())


def test_a_failure_without_subgoals_ranks_by_its_missing_atoms(db):
    result = run(db, "--scenario", "scenario1", "--limit", "50", "--model", "nb", "--json")
    assert result.exit_code == 0, result.output
    point = json.loads(result.stdout)["scenario"]
    assert point["subgoals"] == []
    ranked = point["rankings"]["nb"]["goal-directed"]
    assert all(c["resolve"] == pytest.approx(c["joint"], abs=1e-6) for c in ranked)


def test_a_variant_s_candidates_are_ranked_in_that_variant_s_scene(db):
    """--variant reaches the failure in the layout `llcps solve --variant` would build: the
    candidates' Table-1 inputs carry that scene's geometry, not the canonical one's."""

    def point(*extra):
        result = run(db, "--scenario", "scenario3", "--limit", "1000", "--model", "nb", "--json", *extra)
        assert result.exit_code == 0, result.output
        return json.loads(result.stdout)["scenario"]

    canonical, varied, again = point(), point("--variant", "7"), point("--variant", "7")
    assert (canonical["variant"], varied["variant"]) == (0, 7)
    assert varied == again  # the same variant, the same ranking
    assert varied["candidates"] == canonical["candidates"]  # the same entities and controllers

    def predicted(p):  # Omega's prediction reads the candidates' Table-1 inputs (sizes, colours, places)
        return {c["trial"]: c["outcome"] for c in p["rankings"]["nb"]["most-changes"]}

    assert predicted(varied).keys() == predicted(canonical).keys()
    assert predicted(varied) != predicted(canonical)  # another layout, other inputs


def test_a_variant_without_a_scenario_is_a_usage_error(db):
    result = run(db, "--variant", "3")
    assert result.exit_code == 2
    assert "--variant needs --scenario" in result.output and "Traceback" not in result.output
