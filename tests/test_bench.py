"""``llcps bench``: every figure of the cheap groups is named, finite and has a unit (never timed)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from llcps.bench import GROUPS, Figure, figure, judged, run_bench, unsteady
from llcps.bench import scaling
from llcps.bench.store import TrialPool
from llcps.cli.main import app
from llcps.errors import UnknownNameError

CHEAP = ("store", "ranking")


def test_quick_cheap_groups_give_named_finite_figures() -> None:
    figures = run_bench(quick=True, groups=CHEAP)
    assert {f.name.split(".")[0] for f in figures} == set(CHEAP)
    assert len({f.name for f in figures}) == len(figures)
    for f in figures:
        assert f.name and f.unit and math.isfinite(f.value), f
        assert (f.target is None) == (f.met is None), f


def test_target_check_follows_the_bound() -> None:
    assert figure("g", "x", 1200, "trials/s", at_least=1000).met is True
    assert figure("g", "x", 60, "ms", at_most=50) == Figure("g", "x", 60.0, "ms", "<= 50", False)
    assert figure("g", "x", 1, "s").met is None


def test_a_figure_s_name_is_made_of_its_parts() -> None:
    share = figure("scaling", "core_share", 0.9, "ratio", subject="workers2")
    assert (share.name, share.where, share.group, share.sign) == ("scaling.workers2.core_share", "scaling.workers2", "scaling", "core_share")
    assert figure("scaling", "", 20.0, "s wall", subject="workers1").name == "scaling.workers1"
    assert figure("ranking", "all_measures_1000", 1.0, "ms").name == "ranking.all_measures_1000"


def test_unknown_group_lists_the_known_ones() -> None:
    with pytest.raises(UnknownNameError) as err:
        run_bench(groups=["nope"])
    assert all(name in (err.value.hint or "") + err.value.message for name in GROUPS)


def test_cli_json_is_one_array_of_flat_figures() -> None:
    result = CliRunner().invoke(app, ["bench", "--quick", "--json", "--group", "ranking"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert isinstance(data, list) and data
    for row in data:
        assert {"name", "value", "unit"} <= set(row)
        assert all(not isinstance(v, (dict, list)) for v in row.values())


def test_unsteady_names_a_drifting_bound_and_starved_workers() -> None:
    steady = [
        figure("exploration", "control_loop_drift", -0.03, "ratio"),
        figure("scaling", "core_share", 0.97, "ratio", subject="workers2"),
        figure("exploration", "efficiency", 0.5, "ratio", at_least=0.8),
    ]
    assert unsteady(steady) == []
    said = unsteady([figure("exploration", "control_loop_drift", 0.071, "ratio"), figure("scaling", "core_share", 0.62, "ratio", subject="workers2")])
    assert len(said) == 2
    assert "exploration" in said[0] and "+7.1%" in said[0]
    assert "scaling.workers2" in said[1] and "0.62" in said[1]
    assert unsteady([figure("exploration", "control_loop_drift", -0.06, "ratio")])  # slower after counts too
    episode = unsteady([figure("exploration", "episode_drift", -0.12, "ratio"), figure("exploration", "episode_drift", 0.01, "ratio")])
    assert len(episode) == 1 and "-12.0%" in episode[0]


def test_an_unsteady_group_s_targets_are_neither_met_nor_missed() -> None:
    """A ratio taken while the machine's speed moved is uncertain by as much: the target
    checks of that group are withdrawn, the other groups' stand."""
    figures = [
        figure("exploration", "control_loop_drift", -0.39, "ratio"),
        figure("exploration", "efficiency", 0.95, "ratio", at_least=0.8),
        figure("exploration", "sim_step_rate", 7000.0, "steps/s cpu"),
        figure("scaling", "core_share", 0.97, "ratio", subject="workers2"),
        figure("scaling", "speedup", 1.5, "ratio", at_least=1.7),
        figure("store", "visible_load", 0.9, "s wall", at_most=1),
    ]
    out = {f.name: f for f in judged(figures)}
    assert out["exploration.efficiency"].met is None and "not judged" in out["exploration.efficiency"].note
    assert out["exploration.efficiency"].value == 0.95 and out["exploration.efficiency"].target == ">= 0.8"
    assert out["exploration.sim_step_rate"] == figures[2]
    assert out["scaling.speedup"].met is False and out["store.visible_load"].met is True
    steady = [figure("exploration", "control_loop_drift", 0.01, "ratio"), figure("exploration", "efficiency", 0.75, "ratio", at_least=0.8)]
    assert judged(steady) == steady
    starved = judged([figure("scaling", "core_share", 0.6, "ratio", subject="workers2"), figure("scaling", "speedup", 1.5, "ratio", at_least=1.7)])
    assert starved[1].met is None


def test_naming_the_groups_loads_none_of_them() -> None:
    """``llcps bench --help`` lists the groups without loading what they measure."""
    code = "import sys, llcps.bench; print(sorted(m for m in sys.modules if m.startswith('llcps.bench.') and m != 'llcps.bench.core'))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_trial_pool_cycles_its_own_trials() -> None:
    pool = TrialPool(size=5)
    trials = list(pool.trials(7, "b"))
    assert [t.seed for t in trials] == list(range(7)) and {t.branch for t in trials} == {"b"}
    assert len({t.features[0].volume for t in trials}) == 7  # distinct, though the pool holds 5
    assert trials[5].spec == trials[0].spec
    assert len({c.bodies[0].lo for c in pool.changes(7)}) == 7
    assert TrialPool(size=5).records is not pool.records


def test_scaling_figures_keep_their_names(monkeypatch: pytest.MonkeyPatch) -> None:
    def grid(workers: int, *, cache: bool = True) -> scaling.ExperimentRun:
        return scaling.ExperimentRun(wall=20.0 / workers, task_seconds=30.0, cpu=19.0, status="ok")

    monkeypatch.setattr(scaling, "run_scaling_grid", grid)
    names = [f.name for f in scaling.run()]
    per_run = [f"scaling.workers{w}{c}{s}" for c in ("", ".no_cache") for w in (1, 2) for s in ("", ".task_seconds", ".cpu", ".core_share")]
    assert names == per_run + ["scaling.speedup", "scaling.speedup_no_cache", "scaling.load_average", "scaling.load_average_after"]
