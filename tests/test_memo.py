"""The trial memo: a repeated trial is answered from its first simulation, and an
episode records exactly the same trials with the memo, without it, and from it."""

from __future__ import annotations

from pathlib import Path

import pytest

from llcps.cps.agent import solve
from llcps.cps.episode import SolveConfig
from llcps.domain import ControllerParams, TrialSpec
from llcps.pretrain import pretrain
from llcps.sim.memo import TrialMemo, memo_key
from llcps.store import Store

SPEC = TrialSpec("push", ("block",), ControllerParams(0.4, 0.15, "left"))


def _row(t):
    """What an episode decided and observed, without ids, times and provenance."""
    return (t.source, t.spec, t.features, t.outcome, t.solved, t.sim_steps)


def test_memo_keys_depend_on_every_input() -> None:
    scene, state = {"name": "s"}, b"BULLET-state"
    key = memo_key(scene, state, SPEC, 100)
    assert key == memo_key({"name": "s"}, b"BULLET-state", SPEC, 100)
    other_spec = TrialSpec("push", ("block",), ControllerParams(0.4, 0.15, "right"))
    assert len({key, memo_key({"name": "t"}, state, SPEC, 100), memo_key(scene, b"x", SPEC, 100),
                memo_key(scene, state, other_spec, 100), memo_key(scene, state, SPEC, 99)}) == 5


def test_memo_counts_and_forgets_the_least_recently_used() -> None:
    memo = TrialMemo(capacity=2)
    memo.put(b"a", "A", b"1")  # type: ignore[arg-type]
    memo.put(b"b", "B", b"2")  # type: ignore[arg-type]
    assert memo.get(b"a") == ("A", b"1")  # a is now the most recent
    memo.put(b"c", "C", b"3")  # type: ignore[arg-type]
    assert memo.get(b"b") is None and memo.get(b"c") == ("C", b"3") and len(memo) == 2
    assert (memo.stats.hits, memo.stats.misses) == (2, 1)
    with pytest.raises(ValueError):
        TrialMemo(capacity=0)


def test_episodes_record_the_same_trials_with_and_without_the_memo(tmp_path: Path) -> None:
    config = SolveConfig(scenario="scenario2", budget=8, seed=4)
    memo = TrialMemo()
    with Store.open(str(tmp_path / "memo.db"), create=True) as store:
        pretrain(store, branch="main", n=6, seed=3)
        for name in ("plain", "first", "again"):
            store.create_branch(name, from_branch="main", at="pretrain")
        plain = solve(store, branch="plain", config=config)
        first = solve(store, branch="first", config=config, memo=memo)
        simulated = memo.stats.misses
        again = solve(store, branch="again", config=config, memo=memo)
        rows = {
            name: [_row(t) for t in store.visible_trials(name) if t.source != "pretrain"]
            for name in ("plain", "first", "again")
        }
    assert plain.exploration_trials == first.exploration_trials == again.exploration_trials > 0
    assert plain.status == first.status == again.status
    # plan trials after exploration trials too: the memo's end states feed later physics
    assert sum(1 for r in rows["plain"] if r[0] == "plan") > 1
    assert rows["plain"] == rows["first"] == rows["again"]
    assert simulated == len(rows["first"])  # the first memo run simulated every trial
    assert memo.stats.misses == simulated and memo.stats.hits == len(rows["again"])
