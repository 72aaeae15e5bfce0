"""K' per branch: the operators a branch learned, and how operators fared as plan steps.

A learned operator and an execution record are stamped with their branch's watermark
(its largest visible trial id when they were written), so they are seen by that
branch and by branches forked from it later, like the trials they followed.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from sqlalchemy import insert, select

from llcps import bounded_json
from llcps.errors import StoreError
from llcps.store import visibility
from llcps.store.branches import BranchQueries
from llcps.store.records import ExecutionCounts, ExecutionRecord, OperatorRecord
from llcps.store.tables import Operator, OperatorExecution
from llcps.store.transactions import utc_now
from llcps.store.trials import iso_timestamp


def _context_atoms(row_id: int, context: Any) -> tuple[tuple[str, ...], ...]:
    """A stored execution context, checked: a list of atoms, each a list of 2 to 4 strings."""
    problem = "a malformed context"
    if isinstance(context, str):
        try:
            context = bounded_json.loads(context)
        except ValueError as exc:
            context, problem = None, f"a malformed context ({exc})"
    if not isinstance(context, list) or not all(
        isinstance(atom, list) and 2 <= len(atom) <= 4 and all(isinstance(t, str) for t in atom) for atom in context
    ):
        raise StoreError(
            f"operator execution {row_id} has {problem}",
            hint="the row was not written by llcps; delete it or restore the store from a backup",
        )
    return tuple(sorted(tuple(atom) for atom in context))


class OperatorQueries(BranchQueries):
    """Learned operators and operator executions, written on a branch and read through its chain."""

    def add_operator(
        self,
        *,
        branch: str,
        name: str,
        pddl: str,
        definition: Mapping[str, Any],
        scenario: str | None,
        episode_id: int | None,
    ) -> int:
        """Persist a learned operator on ``branch``, stamped with its current watermark."""
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(Operator).values(
                    branch_id=chain[0].branch_id,
                    name=name,
                    pddl=pddl,
                    definition=dict(definition),
                    scenario=scenario,
                    episode_id=episode_id,
                    watermark=self._max_visible(conn, chain),
                    created_at=utc_now(),
                )
            ).inserted_primary_key[0]

    def visible_operators(self, branch: str | None) -> list[OperatorRecord]:
        """The operators ``branch`` has learned or inherited, oldest first."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            names = {link.branch_id: link.name for link in chain}
            stmt = select(Operator).where(visibility.clause(chain, Operator.branch_id, Operator.watermark)).order_by(Operator.id)
            return [
                OperatorRecord(
                    id=r.id,
                    branch=names[r.branch_id],
                    name=r.name,
                    pddl=r.pddl,
                    definition=r.definition,
                    scenario=r.scenario,
                    episode_id=r.episode_id,
                    watermark=r.watermark,
                    created_at=iso_timestamp(r.created_at) or "",
                )
                for r in conn.execute(stmt)
            ]

    def add_operator_execution(
        self,
        *,
        branch: str,
        operator: str,
        success: bool,
        context: Sequence[Sequence[str]] = (),
        episode_id: int | None = None,
        trial_id: int | None = None,
    ) -> int:
        """Record that ``operator`` ran as a plan step on ``branch``, whether its effects
        held, and its context (the lifted facts over its arguments before it ran).

        Stamped with the branch's watermark, so that it is seen by the branch and by
        branches forked from it later, like the trial it followed.
        """
        atoms = sorted([str(term) for term in atom] for atom in context)
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(OperatorExecution).values(
                    branch_id=chain[0].branch_id,
                    operator=operator,
                    success=bool(success),
                    context=atoms,
                    episode_id=episode_id,
                    trial_id=trial_id,
                    watermark=self._max_visible(conn, chain),
                    created_at=utc_now(),
                )
            ).inserted_primary_key[0]

    def operator_experience(self, branch: str | None) -> list[ExecutionCounts]:
        """Successes and failures of every operator per context, over what ``branch`` sees.

        Raises:
            StoreError: a stored context is not a list of atoms (lists of strings).
        """
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            stmt = (
                select(OperatorExecution.id, OperatorExecution.operator, OperatorExecution.context, OperatorExecution.success)
                .where(visibility.clause(chain, OperatorExecution.branch_id, OperatorExecution.watermark))
                .order_by(OperatorExecution.id)
            )
            counts: dict[tuple[str, tuple[tuple[str, ...], ...]], list[int]] = {}
            for row_id, name, context, success in conn.execute(stmt):
                key = (str(name), _context_atoms(row_id, context))
                counts.setdefault(key, [0, 0])[0 if success else 1] += 1
        return [ExecutionCounts(name, context, s, f) for (name, context), (s, f) in sorted(counts.items())]

    def own_operator_executions(self, branch: str) -> list[ExecutionRecord]:
        """The executions recorded on ``branch`` itself (not inherited), oldest first: what
        a branch moved to another store carries.

        Raises:
            StoreError: a stored context is not a list of atoms (lists of strings).
        """
        with self._read() as conn:
            link = self._chain(conn, branch)[0]
            stmt = select(OperatorExecution).where(OperatorExecution.branch_id == link.branch_id).order_by(OperatorExecution.id)
            return [
                ExecutionRecord(
                    id=r.id,
                    branch=link.name,
                    operator=str(r.operator),
                    success=bool(r.success),
                    context=_context_atoms(r.id, r.context),
                    episode_id=r.episode_id,
                    trial_id=r.trial_id,
                    watermark=int(r.watermark),
                    created_at=iso_timestamp(r.created_at) or "",
                )
                for r in conn.execute(stmt)
            ]
