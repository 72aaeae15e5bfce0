"""Bounded input and safe output, as a user meets them: a scenario file, a results file or a
``--db`` path beyond the documented limits (llcps.limits, docs/scenarios.md "Limits") is
one ``error:``/``hint:`` pair naming the file and field, exit code 2, and the store byte
for byte as it was; every file llcps writes replaces a symbolic link instead of writing
through it (docs/reliability.md lists each case with its test)."""

from __future__ import annotations

import os
import re
import sqlite3
import tomllib
from contextlib import closing
from pathlib import Path
from typing import Any, Callable

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from llcps import limits
from llcps.cli.main import app
from llcps.domain import fluent
from llcps.errors import LlcpsError
from llcps.experiments.rows import COLUMNS, ResultRow, write_rows_csv
from llcps.outputs import written_atomically
from llcps.scenarios import SHIPPED_DIR
from llcps.scenarios.loader import read_text
from llcps.store import Store
from llcps.symbolic import planner
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]


def llcps(*args: str):  # noqa: ANN201 - click Result
    return runner.invoke(app, list(args))


def assert_one_error(result, *needles: str) -> None:  # noqa: ANN001
    """Exit 2, exactly an error and a hint line on stderr, no traceback, nothing on stdout."""
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = result.stderr.splitlines()
    assert [line.split(":", 1)[0] for line in lines] == ["error", "hint"], result.stderr
    assert "Traceback" not in result.output and "internal error" not in result.output and result.stdout == ""
    for needle in needles:
        assert needle in result.stderr, (needle, result.stderr)


def dump(db: Path) -> list[str]:
    """Every row of the store, as SQL."""
    with closing(sqlite3.connect(db)) as conn:
        return list(conn.iterdump())


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / "llcps.db"
    with Store.open(str(path), create=True):
        pass
    return path


def base_scenario() -> dict[str, Any]:
    """Scenario 2's file as data, under a name of its own."""
    data = tomllib.loads((SHIPPED_DIR / "scenario2.toml").read_text(encoding="utf-8"))
    return {**data, "name": "mine", "alias": "mine_alias"}


def blocks(n: int) -> list[dict[str, Any]]:
    """``n`` small blocks on a grid clear of scenario 2's entities."""
    return [
        {"name": f"b{i}", "shape": "box", "color": "red", "size": [0.03, 0.03, 0.03], "x": 0.3 + 0.05 * (i // 4), "y": -0.2 + 0.05 * (i % 4)}
        for i in range(n)
    ]


def nested(depth: int) -> Any:
    value: Any = 0.1
    for _ in range(depth):
        value = [value]
    return value


# -- 1. unbounded input from files ---------------------------------------------------------------

#: name -> (change to scenario 2's data, or the file's raw text; the field the error names)
BAD_FILES: dict[str, tuple[Callable[[dict[str, Any]], Any] | str, str]] = {
    "nan": (lambda d: d["entities"][0].update(x=float("nan")), "entities[0].x: must be a finite number"),
    "inf in a condition": (lambda d: d["conditions"]["novelty"]["entities"]["bin"].update(mass=float("inf")),
                           "conditions.novelty.entities.bin.mass: must be a finite number"),
    "a kilometre away": (lambda d: d["entities"][0].update(x=1000.0), "entities[0].x: must be within +-100"),
    "too many entities": (lambda d: d["entities"].extend(blocks(limits.MAX_ENTITIES)), "entities: 15 items, more than the 12"),
    "thousands of entities": (lambda d: d["entities"].extend(blocks(3000)), "entities: 3003 items, more than the 256"),
    "a rate of 1e300": (lambda d: d.update(grid={"rates": [0.1, 1e300]}), "grid.rates: rates must lie within"),
    "3000 rates": (lambda d: d.update(grid={"rates": [0.01 + i * 1e-4 for i in range(3000)]}), "grid.rates: 3000 items, more than the 256"),
    "9 rates": (lambda d: d.update(grid={"rates": [0.1 * (i + 1) for i in range(9)]}), "grid.rates: 9 values, more than the 8"),
    "deep nesting": ('name = "deep"\ngoal = ["(in can bin)"]\nx = ' + "[" * 5000 + "]" * 5000 + "\n", "nested deeper than the 8 levels"),
    "nesting within tomllib": (lambda d: d.update(grid={"rates": nested(40)}), "grid.rates[0][0][0][0][0][0]: nested deeper than the 8 levels"),
    "a long story": (lambda d: d.update(story="x" * (limits.MAX_TEXT + 1)), "story: 4,097 characters"),
    "contradictory goal": (lambda d: d.update(goal=["(in can bin)", "(not (in can bin))"]), "goal[1]: '(not (in can bin))' contradicts"),
    "too many goal atoms": (lambda d: d.update(goal=["(in can bin)"] * 33), "goal: 33 items, more than the 32"),
    "a wall too thick": (lambda d: d["entities"][1].update(wall=0.5), "entities[1] (bin): container 'bin': wall 0.5 too thick"),
    "a file too large": ("# " + "x" * limits.MAX_SCENARIO_FILE_BYTES + "\n", "larger than the 1,048,576 bytes"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_a_scenario_file_beyond_the_limits_is_refused_before_anything_is_stored(db: Path, tmp_path: Path, case: str) -> None:
    change, needle = BAD_FILES[case]
    path = tmp_path / "mine.toml"
    if isinstance(change, str):
        path.write_text(change, encoding="utf-8")
    else:
        data = base_scenario()
        change(data)
        path.write_text(tomli_w.dumps(data), encoding="utf-8")
    before = dump(db)
    assert_one_error(llcps("--db", str(db), "solve", str(path), "--budget", "0"), f"{path}", needle)
    assert dump(db) == before


@pytest.mark.parametrize("kind", ["device", "fifo", "directory"])
def test_every_path_the_cli_reads_must_be_a_regular_file(db: Path, tmp_path: Path, kind: str) -> None:
    """/dev/zero would be read until memory ran out, a FIFO would hang: each is one error."""
    if kind == "device":
        path = Path("/dev/zero")
    elif kind == "fifo":
        path = tmp_path / "pipe.toml"
        os.mkfifo(path)
    else:
        path = tmp_path / "dir.toml"
        path.mkdir()
    before = dump(db)
    reads = [
        ["--db", str(db), "solve", str(path), "--budget", "0"],
        ["--db", str(db), "inspect", "trials", "--scenario", str(path)],
        ["scenario", "show", str(path)],
    ]
    if kind != "directory":  # a directory is a results directory to report on, and refused as --db already
        reads += [["experiment", "report", str(path)], ["--db", str(path), "db", "status"]]
    expected = {"device": "a device", "fifo": "a FIFO", "directory": "a directory"}[kind]
    for args in reads:
        assert_one_error(llcps(*args), expected)
    assert dump(db) == before


def test_the_planner_is_bounded_by_the_states_it_holds() -> None:
    """A goal no plan reaches, among as many entities as a scene may hold: the search gives up
    holding ``max_states`` states (an error, exit 1), instead of growing until memory runs out."""
    kb = KnowledgeBase.default()
    names = [f"b{i}" for i in range(limits.MAX_ENTITIES - 1)]
    init = frozenset(fluent("visible", n) for n in [*names, "bin"]) | frozenset(fluent("on", n, "table") for n in names)
    task = Task.from_scene(entities={**{n: "object" for n in names}, "bin": "container"}, fixtures=(), init=init,
                           goal_pos=[fluent("holding", "b0")])  # fmt: skip
    assert len(planner.ground(kb, task)) <= limits.MAX_GROUND_ACTIONS
    with pytest.raises(planner.PlanningLimitError, match="holding 500 states"):
        planner.plan(kb, task, max_states=500)


# -- the property: any file within the limits loads, any outside is refused naming its field ----

WITHIN = {
    "extra entities": st.integers(0, limits.MAX_ENTITIES - 3),
    "rates": st.lists(st.floats(limits.MIN_RATE, limits.MAX_RATE), min_size=1, max_size=limits.MAX_GRID_VALUES, unique=True),
    "movement_magnitudes": st.lists(st.floats(0, limits.MAX_MOVEMENT_MAGNITUDE), min_size=1, max_size=limits.MAX_GRID_VALUES, unique=True),
    "mass": st.floats(1e-3, limits.MAX_MASS),
    "story": st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=limits.MAX_TEXT),
}
BEYOND = {
    "extra entities": st.integers(limits.MAX_ENTITIES - 2, limits.MAX_ENTITIES + 20),
    "rates": st.one_of(
        st.lists(st.floats(limits.MIN_RATE, limits.MAX_RATE), min_size=limits.MAX_GRID_VALUES + 1, max_size=40, unique=True),
        st.lists(st.one_of(st.floats(limits.MAX_RATE, exclude_min=True), st.just(float("nan")), st.floats(-1e300, limits.MIN_RATE, exclude_max=True)), min_size=1, max_size=3),
    ),
    "movement_magnitudes": st.lists(st.one_of(st.floats(limits.MAX_MOVEMENT_MAGNITUDE, exclude_min=True), st.just(float("-inf"))), min_size=1, max_size=3),
    "mass": st.one_of(st.floats(limits.MAX_MASS, exclude_min=True), st.just(float("nan")), st.floats(max_value=0)),
    "story": st.text(min_size=limits.MAX_TEXT + 1, max_size=limits.MAX_TEXT + 50),
}
FIELD = {"extra entities": "entities", "rates": "grid.rates", "movement_magnitudes": "grid.movement_magnitudes",
         "mass": "entities[0].mass", "story": "story"}  # fmt: skip


def _apply(data: dict[str, Any], key: str, value: Any) -> None:
    if key == "extra entities":
        data["entities"].extend(blocks(value))
    elif key in ("rates", "movement_magnitudes"):
        data.setdefault("grid", {})[key] = value
    elif key == "mass":
        data["entities"][0]["mass"] = value
    else:
        data[key] = value


@settings(max_examples=60, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_any_file_within_the_limits_loads_and_any_beyond_is_refused_naming_the_field(data: st.DataObject) -> None:
    key = data.draw(st.sampled_from(sorted(WITHIN)))
    beyond = data.draw(st.booleans())
    value = data.draw((BEYOND if beyond else WITHIN)[key])
    scenario = base_scenario()
    _apply(scenario, key, value)
    text = tomli_w.dumps(scenario)
    if not beyond:
        assert read_text(text, where="mine.toml").name == "mine"
        return
    with pytest.raises(LlcpsError) as refused:
        read_text(text, where="mine.toml")
    assert refused.value.message.startswith(f"mine.toml: {FIELD[key]}"), refused.value.message
    assert refused.value.hint


# -- 6. output paths through symbolic links ------------------------------------------------------


def test_scenario_render_replaces_a_link_instead_of_writing_through_it(tmp_path: Path) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "scenario1_original.png").symlink_to(victim)
    result = llcps("scenario", "render", "scenario1", "--out-dir", str(out), "--condition", "original")
    assert result.exit_code == 0, result.output
    assert victim.read_text() == "precious\n"
    written = out / "scenario1_original.png"
    assert not written.is_symlink() and written.read_bytes().startswith(b"\x89PNG")


def test_written_atomically_replaces_links_and_writes_system_devices_directly(tmp_path: Path) -> None:
    victim = tmp_path / "victim"
    victim.write_text("precious")
    link = tmp_path / "link.csv"
    link.symlink_to(victim)
    dangling = tmp_path / "dangling.csv"
    dangling.symlink_to(tmp_path / "made-through-the-link")
    for path in (link, dangling):
        with written_atomically(path, what="--out") as target:
            target.write_text("new")
        assert not path.is_symlink() and path.read_text() == "new"
    assert victim.read_text() == "precious" and not (tmp_path / "made-through-the-link").exists()
    with pytest.raises(LlcpsError, match="No space left"), written_atomically("/dev/full", what="--out") as target:
        target.write_text("x")


#: Calls that write a file: only llcps/outputs.py makes them; every other writer goes through it.
_WRITES = re.compile(r"\.write_text\(|\.write_bytes\(|open\([^)]*[\"'][wax]b?[\"']|\.savefig\(|\.save\((?!\))")


#: Lines that write through it: into its temporary ``target``, a GIF through ``Recorder.save``,
#: a member of an in-memory archive.
_THROUGH_THE_HELPER = re.compile(r"\btarget\b|speedup=|archive\.open\(|^\s*rec\.save\(\"docs/")


def test_every_file_llcps_writes_goes_through_the_one_helper() -> None:
    allowed = {
        "llcps/outputs.py",
        "llcps/sim/robot.py",  # the robot's mesh cache, written once into llcps' own cache directory
    }
    offenders = []
    for path in sorted((ROOT / "llcps").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel in allowed:
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if _WRITES.search(line) and not _THROUGH_THE_HELPER.search(line):
                offenders.append(f"{rel}:{number}: {line.strip()}")
    assert offenders == []


# -- 7. reports from bad results files -----------------------------------------------------------


def _results(tmp_path: Path) -> Path:
    rows = [
        ResultRow(preset="smoke", model="nb", measure="most-changes", pretrain_size=4, condition=condition, seed=seed,
                  scenario=scenario, solved=True, exploration_trials=3 + seed, sim_seconds=1.5, wall_seconds=2.0,
                  episode_id=None, branch=f"exp-smoke-nb-most-changes-p4-{condition}-s{seed}-{scenario}")
        for condition in ("reset", "update") for seed in (0, 1) for scenario in ("scenario1", "scenario2")
    ]  # fmt: skip
    out = tmp_path / "results"
    out.mkdir()
    return write_rows_csv(rows, out / "results.csv")


BAD_RESULTS = {
    "nan": ("sim_seconds", "nan", "column 'sim_seconds': must be a finite number"),
    "inf": ("wall_seconds", "inf", "column 'wall_seconds': must be a finite number"),
    "negative count": ("exploration_trials", "-40", "column 'exploration_trials': must be a whole number from 0"),
    "negative seconds": ("sim_seconds", "-1.0", "column 'sim_seconds': must be a finite number of seconds, zero or more"),
    "wrong type": ("exploration_trials", "3.5", "column 'exploration_trials': bad value '3.5'"),
    "negative seed": ("seed", "-1", "column 'seed': must be a whole number"),
    "missing column": ("solved", None, "missing column(s) solved"),
}


@pytest.mark.parametrize("case", list(BAD_RESULTS))
def test_a_report_from_a_bad_results_file_names_row_and_column(tmp_path: Path, case: str) -> None:
    column, value, needle = BAD_RESULTS[case]
    path = _results(tmp_path)
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    index = header.index(column)
    cells = [line.split(",") for line in lines]
    if value is None:
        cells = [c[:index] + c[index + 1 :] for c in cells]
    else:
        cells[3][index] = value  # the third row, on line 4
    path.write_text("\n".join(",".join(c) for c in cells) + "\n")
    before = sorted(p.name for p in path.parent.iterdir())
    result = llcps("experiment", "report", str(path.parent))
    assert_one_error(result, f"{path}: row {1 if value is None else 3}", needle)
    assert sorted(p.name for p in path.parent.iterdir()) == before  # no report written
    assert set(COLUMNS) >= {column}


@pytest.mark.parametrize(("column", "value"), [("model", ["nb"]), ("scenario", {"name": "scenario1"}), ("resolving_pick", 5), ("branch", 3.5)])
def test_a_json_results_file_with_a_non_text_value_in_a_text_column_names_row_and_column(tmp_path: Path, column: str, value: Any) -> None:
    """A JSON number, list or object where a text column belongs is an error, not its str()."""
    import json

    from llcps.analysis.results import ResultsTable

    path = ResultsTable.read(_results(tmp_path)).write_json(tmp_path / "results.json")
    data = json.loads(path.read_text())
    rows = data["rows"] if isinstance(data, dict) else data
    rows[2][column] = value
    path.write_text(json.dumps(data))
    result = llcps("experiment", "report", str(path))
    assert_one_error(result, f"{path}: row 3", f"column {column!r}: bad value")
    assert json.loads(path.read_text()) == data  # nothing rewritten


def test_a_stored_scene_is_held_to_the_same_limits() -> None:
    """The scene of a stored snapshot is read through ``SceneSpec.from_dict``: the entity bound of
    a file holds for it too."""
    from llcps.sim.builders import solid
    from llcps.sim.specs import SceneSpec

    entities = [solid(f"b{i}", "box", "red", (0.03, 0.03, 0.03), at=(0.3 + 0.05 * (i // 4), -0.2 + 0.05 * (i % 4))) for i in range(limits.MAX_ENTITIES + 1)]
    data = SceneSpec(tuple(entities[:-1])).to_dict()
    assert len(SceneSpec.from_dict(data).entities) == limits.MAX_ENTITIES
    data["entities"].append(entities[-1].to_dict())
    with pytest.raises(LlcpsError, match=f"more than {limits.MAX_ENTITIES} entities"):
        SceneSpec.from_dict(data)
