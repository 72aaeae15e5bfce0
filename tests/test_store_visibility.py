"""The branch-visibility algebra on its own (no store): random trees of branches and trials
against the rule written out recursively, and rows that do not form a tree."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sqlalchemy import Column, Integer, MetaData, Table, create_engine, insert, select

from llcps.errors import StoreError, UnknownNameError
from llcps.store.visibility import BranchRow, Link, blocking_children, chain, clause, sees


@st.composite
def histories(draw: st.DrawFn) -> tuple[list[BranchRow], list[tuple[int, int]]]:
    """Branches forked over time from a growing set of trials, as the store makes them.

    Returns:
        Branch rows (main first) and trials as (id, owning branch id), ids increasing.
    """
    rows = [BranchRow(1, "main", None, 0)]
    trials: list[tuple[int, int]] = []
    next_id = 1
    for _ in range(draw(st.integers(0, 25))):
        if draw(st.booleans()):
            owner = draw(st.sampled_from(rows)).id
            for _ in range(draw(st.integers(1, 3))):
                trials.append((next_id, owner))
                next_id += 1
        else:
            parent = draw(st.sampled_from(rows))
            fork = draw(st.integers(0, next_id - 1))  # any id up to the newest, as `--at` allows
            rows.append(BranchRow(len(rows) + 1, f"b{len(rows) + 1}", parent.id, fork))
    return rows, trials


def reference_visible(rows: list[BranchRow], trials: list[tuple[int, int]], branch_id: int) -> set[int]:
    """visible(B) = own(B) ∪ {t ∈ visible(parent(B)) : t.id <= fork(B)}, as written in docs/store.md."""
    row = next(r for r in rows if r.id == branch_id)
    own = {t for t, owner in trials if owner == branch_id}
    if row.parent_id is None:
        return own
    return own | {t for t in reference_visible(rows, trials, row.parent_id) if t <= row.fork_point}


@settings(max_examples=200, deadline=None)
@given(histories())
def test_the_chain_gives_the_recursive_rule(history: tuple[list[BranchRow], list[tuple[int, int]]]) -> None:
    rows, trials = history
    for row in rows:
        links = chain(rows, row.name)
        assert {t for t, owner in trials if sees(links, owner, t)} == reference_visible(rows, trials, row.id)
        assert links[0] == Link(row.id, row.name, None) and links[-1].branch_id == 1
        limits = [link.limit for link in links[1:]]
        assert limits == sorted(limits, reverse=True)  # a grandparent is seen up to the smaller fork


@settings(max_examples=100, deadline=None)
@given(histories(), st.data())
def test_a_new_trial_changes_only_its_own_branch(history: tuple[list[BranchRow], list[tuple[int, int]]], data: st.DataObject) -> None:
    """Ids only grow: a new trial is seen by its branch alone, and nothing seen before changes."""
    rows, trials = history
    owner = data.draw(st.sampled_from(rows)).id
    newest = max([t for t, _ in trials] + [r.fork_point for r in rows]) + 1
    before = {r.id: reference_visible(rows, trials, r.id) for r in rows}
    for row in rows:
        links = chain(rows, row.name)
        assert sees(links, owner, newest) == (row.id == owner)
        after = {t for t, o in [*trials, (newest, owner)] if sees(links, o, t)}
        assert after - {newest} == before[row.id]


@settings(max_examples=50, deadline=None)
@given(histories())
def test_the_sql_clause_selects_what_sees_accepts(history: tuple[list[BranchRow], list[tuple[int, int]]]) -> None:
    rows, trials = history
    table = Table("t", MetaData(), Column("id", Integer, primary_key=True), Column("branch_id", Integer))
    engine = create_engine("sqlite://")
    with engine.begin() as conn:
        table.create(conn)
        if trials:
            conn.execute(insert(table), [{"id": t, "branch_id": owner} for t, owner in trials])
        for row in rows:
            links = chain(rows, row.name)
            selected = set(conn.scalars(select(table.c.id).where(clause(links, table.c.branch_id, table.c.id))))
            assert selected == {t for t, owner in trials if sees(links, owner, t)}


def test_rows_that_are_not_a_tree_are_a_store_error() -> None:
    cycle = [BranchRow(1, "main", None, 0), BranchRow(2, "a", 3, 5), BranchRow(3, "b", 2, 5)]
    with pytest.raises(StoreError, match="cycle"):
        chain(cycle, "a")
    with pytest.raises(StoreError, match="does not exist"):
        chain([BranchRow(1, "main", None, 0), BranchRow(2, "a", 9, 0)], "a")
    with pytest.raises(StoreError, match="fork point"):
        chain([BranchRow(1, "main", None, 0), BranchRow(2, "a", 1, -4)], "a")
    with pytest.raises(UnknownNameError, match="main"):
        chain([BranchRow(1, "main", None, 0)], "nope")


@given(st.lists(st.integers(0, 50), max_size=6), st.none() | st.integers(1, 50))
def test_a_child_blocks_a_removal_it_would_notice(forks: list[int], first_removed: int | None) -> None:
    children = [BranchRow(i + 2, f"c{i}", 1, f) for i, f in enumerate(forks)]
    blocking = blocking_children(children, first_removed)
    assert blocking == [c.name for c in children if first_removed is not None and c.fork_point >= first_removed]
