"""The branch-visibility algebra, apart from any database.

A branch B with parent P forked at trial id f sees its own rows plus the rows P
sees with id <= f (recursively, so the limit for a grandparent is the smaller of
the two fork points):

    visible(B) = own(B) ∪ { t ∈ visible(parent(B)) : t.id <= fork(B) }

Flattened, that is a *chain*: B itself with no limit, then each ancestor with the
smallest fork point on the way to it. Learned operators and world models follow the
same rule with their watermark (the largest trial id visible when they were made)
in place of the id.

The rule needs trial ids that commit in increasing order: then whatever a branch
saw up to id w stays exactly that set, and a fork at the parent's largest visible
id sees a fixed prefix. The store guarantees it by serializing writers (SQLite:
``BEGIN IMMEDIATE``; PostgreSQL: a transaction-level advisory lock), see
docs/reliability.md.

Branch rows come from the database, so they are untrusted: a parent cycle, a
missing parent or a negative fork point is a :class:`StoreError`, not a hang.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Sequence

from sqlalchemy import ColumnElement, and_, false, or_

from llcps.errors import StoreError, UnknownNameError

_REPAIR = "the branches table was changed outside llcps; restore the database from a copy"


@dataclass(frozen=True)
class BranchRow:
    """What visibility needs of a branch row."""

    id: int
    name: str
    parent_id: int | None
    fork_point: int


@dataclass(frozen=True)
class Link:
    """One branch of a visibility chain and the largest id visible from it (None: all)."""

    branch_id: int
    name: str
    limit: int | None


class Tree:
    """Branch rows indexed once, so the chains of every branch take time linear in their depth.

    Rows are anything with ``id``, ``name``, ``parent_id`` and ``fork_point``
    (:class:`BranchRow`, or the database's rows themselves).
    """

    def __init__(self, rows: Iterable[Any]) -> None:
        self.rows = list(rows)
        self.by_id = {r.id: r for r in self.rows}
        self.by_name: dict[str, Any] = {}
        for r in self.rows:
            self.by_name.setdefault(r.name, r)

    def chain(self, name: str) -> list[Link]:
        """The visibility chain of branch ``name``: itself, then its ancestors with their limits.

        Raises:
            UnknownNameError: no branch of that name (the message lists the known ones).
            StoreError: the rows do not form a tree (a cycle, a missing parent, a bad fork point).
        """
        row = self.by_name.get(name)
        if row is None:
            raise UnknownNameError("branch", name, [r.name for r in self.rows])
        links: list[Link] = []
        seen: set[int] = set()
        limit: int | None = None
        while True:
            if row.id in seen:
                raise StoreError(f"branch {name!r} descends from itself (a cycle of parents)", hint=_REPAIR)
            seen.add(row.id)
            links.append(Link(row.id, row.name, limit))
            if row.parent_id is None:
                return links
            if not isinstance(row.fork_point, int) or row.fork_point < 0:
                raise StoreError(f"branch {row.name!r} has an invalid fork point {row.fork_point!r}", hint=_REPAIR)
            parent = self.by_id.get(row.parent_id)
            if parent is None:
                raise StoreError(f"branch {row.name!r} has a parent that does not exist (id {row.parent_id})", hint=_REPAIR)
            limit = row.fork_point if limit is None else min(limit, row.fork_point)
            row = parent


def chain(rows: Sequence[BranchRow], name: str) -> list[Link]:
    """The visibility chain of branch ``name`` among ``rows`` (see :meth:`Tree.chain`)."""
    return Tree(rows).chain(name)


def sees(links: Sequence[Link], branch_id: int, position: int) -> bool:
    """Whether a row of ``branch_id`` at ``position`` (trial id or watermark) is visible on the chain."""
    for link in links:
        if link.branch_id == branch_id:
            return link.limit is None or position <= link.limit
    return False


def clause(links: Sequence[Link], branch_col: Any, position_col: Any) -> ColumnElement[bool]:
    """:func:`sees` as an SQL condition on a table's branch and position columns."""
    terms = [
        branch_col == link.branch_id if link.limit is None else and_(branch_col == link.branch_id, position_col <= link.limit)
        for link in links
    ]
    return or_(*terms) if terms else false()


def inherited_limit(links: Sequence[Link]) -> int | None:
    """The largest position a branch inherits from its parent (None for a root)."""
    return links[1].limit if len(links) > 1 else None


def blocking_children(children: Iterable[BranchRow], first_removed: int | None) -> list[str]:
    """Children that still see something a removal starting at ``first_removed`` would take away."""
    if first_removed is None:
        return []
    return [r.name for r in children if r.fork_point >= first_removed]
