"""Trial changes between :class:`~llcps.domain.TrialChange` and ``trial_changes`` rows.

A change is kept in its own table keyed by trial id (the trials table and its hot
decoder stay as they are). What is read back is untrusted: every atom and body is
checked before it becomes a domain object, and anything malformed is one
:class:`~llcps.errors.LlcpsError`. Exploration trials of one episode share their
start state and scene, so decoded states and body lists are shared too.
"""

from __future__ import annotations

import json
from typing import Any, Iterable, Sequence

from sqlalchemy import Text, type_coerce

from llcps.domain import CHANGE_SOURCES, Body, Fluent, TrialChange, fluent
from llcps.errors import LlcpsError
from llcps.store.schema import TrialChangeRow

#: Source of a row that records that a trial's change could not be recovered.
UNKNOWN = "unknown"

#: Columns read for a change, in the order :class:`ChangeDecoder` unpacks them.
CHANGE_COLUMNS = (
    TrialChangeRow.trial_id,
    TrialChangeRow.source,
    type_coerce(TrialChangeRow.before, Text),
    type_coerce(TrialChangeRow.added, Text),
    type_coerce(TrialChangeRow.deleted, Text),
    type_coerce(TrialChangeRow.bodies, Text),
)

_HINT = "the stored trial change is damaged; `llcps db upgrade --replay-changes` recovers it from the trial's start state"
#: Bounds that keep a crafted row from costing much (a real scene has a few dozen atoms).
MAX_ATOMS = 10_000
MAX_BODIES = 1_000


def _atoms(atoms: Iterable[Fluent]) -> list[list[str]]:
    return [list(a) for a in sorted(atoms)]


def change_row(trial_id: int, change: TrialChange | None) -> dict[str, Any]:
    """The column values of a trial's change; ``None`` records it as unknown."""
    if change is None:
        return {"trial_id": trial_id, "source": UNKNOWN, "before": [], "added": [], "deleted": [], "bodies": []}
    return {
        "trial_id": trial_id,
        "source": change.source,
        "before": _atoms(change.before),
        "added": _atoms(change.added),
        "deleted": _atoms(change.deleted),
        "bodies": [b.as_dict() for b in change.bodies],
    }


def _json(value: Any) -> Any:
    if not isinstance(value, str):
        return value
    try:
        return json.loads(value)
    except ValueError:
        raise LlcpsError("a stored trial change is not valid JSON", hint=_HINT) from None


def _atom(value: Any) -> Fluent:
    if (
        not isinstance(value, list)
        or not 1 <= len(value) <= 3
        or not all(isinstance(part, str) and part for part in value)
    ):
        raise LlcpsError(f"a stored trial change holds a malformed atom {str(value)[:60]}", hint=_HINT)
    return fluent(*value)


def _atom_set(value: Any, known: dict[Any, Fluent] | None = None) -> frozenset[Fluent]:
    """The atoms of a stored state; ``known`` maps atoms already checked (as tuples of
    their parts) to their fluents: the same few atoms recur across a training set."""
    decoded = _json(value)
    if not isinstance(decoded, list) or len(decoded) > MAX_ATOMS:
        raise LlcpsError("a stored trial change's atoms are not a list of atoms", hint=_HINT)
    if known is None:
        return frozenset(_atom(a) for a in decoded)
    atoms = []
    for a in decoded:
        try:
            key = tuple(a) if type(a) is list else None
            found = known.get(key) if key is not None else None
        except TypeError:  # a part that cannot be hashed: _atom names the problem
            found = None
        if found is None:
            found = _atom(a)
            if len(known) < MAX_ATOMS:
                known[tuple(a)] = found
        atoms.append(found)
    return frozenset(atoms)


def _bodies(value: Any) -> tuple[Body, ...]:
    decoded = _json(value)
    if not isinstance(decoded, list) or len(decoded) > MAX_BODIES:
        raise LlcpsError("a stored trial change's bodies are not a list", hint=_HINT)
    bodies = []
    for item in decoded:
        try:
            bodies.append(Body.from_dict(item))
        except (ValueError, TypeError) as exc:
            raise LlcpsError(f"a stored trial change holds a malformed body: {exc}", hint=_HINT) from None
    return tuple(bodies)


class ChangeDecoder:
    """Builds TrialChanges from rows of :data:`CHANGE_COLUMNS`, sharing repeated parts."""

    def __init__(self) -> None:
        self._states: dict[str, frozenset[Fluent]] = {}
        self._bodies: dict[str, tuple[Body, ...]] = {}
        self._atoms: dict[Any, Fluent] = {}

    def _state(self, text: Any) -> frozenset[Fluent]:
        if not isinstance(text, str):
            return _atom_set(text, self._atoms)
        found = self._states.get(text)
        if found is None:
            found = self._states[text] = _atom_set(text, self._atoms)
        return found

    def _body_list(self, text: Any) -> tuple[Body, ...]:
        if not isinstance(text, str):
            return _bodies(text)
        found = self._bodies.get(text)
        if found is None:
            found = self._bodies[text] = _bodies(text)
        return found

    def decode_result(self, result: Any, batch: int = 1000) -> list[TrialChange]:
        """The known changes of every row of a query result (anything with ``fetchmany``),
        read a batch at a time (see :meth:`llcps.store.trials.TrialDecoder.decode_result`).

        Raises:
            LlcpsError: a row is malformed (untrusted input).
        """
        out: list[TrialChange] = []
        while rows := result.fetchmany(batch):
            out += [change for change in map(self.decode, rows) if change is not None]
        return out

    def decode(self, row: Sequence[Any]) -> TrialChange | None:
        """One row's change; None when it is recorded as unknown.

        Raises:
            LlcpsError: the row is malformed (untrusted input).
        """
        trial_id, source, before, added, deleted, bodies = row
        if source not in CHANGE_SOURCES:
            raise LlcpsError(f"trial {trial_id}'s change has unknown source {str(source)[:20]!r}", hint=_HINT)
        if source == UNKNOWN:
            return None
        try:
            return TrialChange(
                before=self._state(before),
                added=self._state(added),
                deleted=self._state(deleted),
                bodies=self._body_list(bodies),
                source=source,
                trial_id=int(trial_id),
            )
        except ValueError as exc:
            raise LlcpsError(f"trial {trial_id}'s stored change is inconsistent: {exc}", hint=_HINT) from None
