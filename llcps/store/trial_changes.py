"""Trial changes between :class:`~llcps.trial_records.TrialChange` and ``trial_changes`` rows.

A change is kept in its own table keyed by trial id (the trials table and its hot
decoder stay as they are), its states and its scene each packed into one binary
value (:func:`pack_atoms`, :func:`pack_bodies`): a fit reads every visible trial's
change. What is read back is untrusted: every atom and body is checked before it
becomes a domain object, and anything malformed is one
:class:`~llcps.errors.LlcpsError`. Exploration trials of one episode share their
start state and scene, so decoded states and body lists are shared too.
"""

from __future__ import annotations

import math
import struct
from dataclasses import fields
from functools import lru_cache
from typing import Any, Iterable, Sequence

from llcps.domain import BODY_KINDS, CHANGE_SOURCES, SHAPES, Fluent, fluent
from llcps.trial_records import Body, TrialChange
from llcps.errors import LlcpsError
from llcps.store.tables import TrialChangeRow

#: Source of a row that records that a trial's change could not be recovered.
UNKNOWN = "unknown"

#: Columns read for a change, in the order :class:`ChangeDecoder` unpacks them.
CHANGE_COLUMNS = (
    TrialChangeRow.trial_id,
    TrialChangeRow.source,
    TrialChangeRow.before,
    TrialChangeRow.added,
    TrialChangeRow.deleted,
    TrialChangeRow.bodies,
)

_HINT = "the stored trial change is damaged; `llcps db upgrade --replay-changes` recovers it from the trial's start state"
#: Bounds that keep a crafted row from costing much (a real scene has a few dozen atoms).
MAX_ATOMS = 10_000
MAX_BODIES = 1_000


#: Packed states (``before``, ``added``, ``deleted``): a layout byte, then the atoms as
#: UTF-8 text, sorted, each atom's predicate and arguments joined by US (0x1f), the atoms
#: joined by RS (0x1e).
ATOMS_LAYOUT = 1
_SEPARATOR = "\x1f"
_ATOM_SEPARATOR = "\x1e"


def pack_atoms(atoms: Iterable[Fluent]) -> bytes:
    """The stored form of a set of atoms (see :data:`ATOMS_LAYOUT`)."""
    texts = []
    for atom in sorted(atoms):
        if not 1 <= len(atom) <= 3 or any(not part or _SEPARATOR in part or _ATOM_SEPARATOR in part for part in atom):
            raise LlcpsError(f"an atom needs one to three names without control characters: {atom!r}")
        texts.append(_SEPARATOR.join(atom))
    if len(texts) > MAX_ATOMS:
        raise LlcpsError(f"a state has at most {MAX_ATOMS} atoms, not {len(texts)}")
    return bytes((ATOMS_LAYOUT,)) + _ATOM_SEPARATOR.join(texts).encode()


def unpack_atoms(data: bytes, known: dict[str, Fluent] | None = None) -> frozenset[Fluent]:
    """Read :func:`pack_atoms`'s bytes back, checking every atom (they come from a database).

    Args:
        known: atoms already checked, by their text (a training set holds few distinct
            atoms); filled with the new ones.

    Raises:
        LlcpsError: the bytes do not have the layout, or hold a malformed atom.
    """
    try:
        if data[0] != ATOMS_LAYOUT:
            raise ValueError
        text = bytes(data[1:]).decode()
    except (IndexError, TypeError, ValueError):  # UnicodeDecodeError is a ValueError
        raise LlcpsError("a stored trial change's atoms are malformed", hint=_HINT) from None
    if not text:
        return frozenset()
    texts = text.split(_ATOM_SEPARATOR)
    if len(texts) > MAX_ATOMS:
        raise LlcpsError("a stored trial change's atoms are malformed", hint=_HINT)
    known = {} if known is None else known
    atoms = []
    for atom_text in texts:
        found = known.get(atom_text)
        if found is None:
            parts = atom_text.split(_SEPARATOR)
            if not 1 <= len(parts) <= 3 or not all(parts):
                raise LlcpsError(f"a stored trial change holds a malformed atom {atom_text[:60]!r}", hint=_HINT)
            found = fluent(*parts)
            if len(known) < MAX_ATOMS:
                known[atom_text] = found
        atoms.append(found)
    return frozenset(atoms)


#: Packed bodies: a layout byte, the body count (two bytes, little-endian), per body nine
#: little-endian doubles (lo, hi and centre), then each body's "name<US>kind<US>shape" as
#: UTF-8 text (an empty shape for a fixture), joined by US (0x1f).
BODIES_LAYOUT = 1
_BODY_KINDS = frozenset(BODY_KINDS)
_SHAPES = frozenset(SHAPES)


@lru_cache(maxsize=64)
def _doubles(n: int) -> struct.Struct:
    return struct.Struct(f"<{9 * n}d")


def pack_bodies(bodies: Sequence[Body]) -> bytes:
    """The stored form of a scene's bodies (see :data:`BODIES_LAYOUT`)."""
    if len(bodies) > MAX_BODIES:
        raise LlcpsError(f"a scene has at most {MAX_BODIES} bodies, not {len(bodies)}")
    names = []
    for b in bodies:
        parts = (b.name, b.kind, b.shape or "")
        if any(_SEPARATOR in part for part in parts):
            raise LlcpsError(f"a body's name, kind or shape cannot hold control characters: {parts!r}")
        names += parts
    numbers = [v for b in bodies for v in (*b.lo, *b.hi, *b.centre)]
    return bytes((BODIES_LAYOUT,)) + len(bodies).to_bytes(2, "little") + _doubles(len(bodies)).pack(*numbers) + _SEPARATOR.join(names).encode()


def unpack_bodies(data: bytes) -> tuple[Body, ...]:
    """Read :func:`pack_bodies`'s bytes back, checking every field (they come from a database).

    Raises:
        LlcpsError: the bytes do not have the layout, or describe no valid body.
    """
    try:
        if data[0] != BODIES_LAYOUT:
            raise ValueError
        n = int.from_bytes(data[1:3], "little")
        if n > MAX_BODIES:
            raise ValueError
        numbers = _doubles(n).unpack_from(data, 3)
        text = bytes(data[3 + 72 * n :]).decode()
    except (IndexError, TypeError, ValueError, struct.error):  # UnicodeDecodeError is a ValueError
        raise LlcpsError("a stored trial change's bodies are malformed", hint=_HINT) from None
    parts = text.split(_SEPARATOR) if n else []
    if len(parts) != 3 * n or (not n and text):
        raise LlcpsError("a stored trial change's bodies are malformed", hint=_HINT)
    if not math.isfinite(sum(numbers)) and not all(map(math.isfinite, numbers)):
        raise LlcpsError("a stored trial change holds a malformed body: a coordinate is not a finite number", hint=_HINT)
    new, set_dict = object.__new__, object.__setattr__
    bodies = []
    for i in range(n):
        name, kind, shape = parts[3 * i : 3 * i + 3]
        if not name or kind not in _BODY_KINDS or (shape and shape not in _SHAPES):
            raise LlcpsError(f"a stored trial change holds a malformed body ({name[:20]!r}, {kind[:20]!r}, {shape[:20]!r})", hint=_HINT)
        at = 9 * i
        body = new(Body)  # every field checked above, as Body.__post_init__ would
        set_dict(
            body,
            "__dict__",
            {
                "name": name,
                "kind": kind,
                "shape": shape or None,
                "lo": numbers[at : at + 3],
                "hi": numbers[at + 3 : at + 6],
                "centre": numbers[at + 6 : at + 9],
            },
        )
        bodies.append(body)
    return tuple(bodies)


if {f.name for f in fields(Body)} != {"name", "kind", "shape", "lo", "hi", "centre"}:  # pragma: no cover
    raise ImportError("llcps.store.trial_changes packs fields that Body does not have")


def change_row(trial_id: int, change: TrialChange | None) -> dict[str, Any]:
    """The column values of a trial's change; ``None`` records it as unknown."""
    if change is None:
        nothing = pack_atoms(())
        return {"trial_id": trial_id, "source": UNKNOWN, "before": nothing, "added": nothing, "deleted": nothing, "bodies": pack_bodies(())}
    return {
        "trial_id": trial_id,
        "source": change.source,
        "before": pack_atoms(change.before),
        "added": pack_atoms(change.added),
        "deleted": pack_atoms(change.deleted),
        "bodies": pack_bodies(change.bodies),
    }


def _as_bytes(value: Any) -> bytes:
    """A binary column's value as bytes: a driver's memoryview copied, any other type
    (a row changed outside llcps) as no bytes, which no layout accepts."""
    if type(value) is bytes:
        return value
    return bytes(value) if isinstance(value, (bytearray, memoryview)) else b""


class ChangeDecoder:
    """Builds TrialChanges from rows of :data:`CHANGE_COLUMNS`, sharing repeated parts."""

    def __init__(self) -> None:
        self._states: dict[bytes, frozenset[Fluent]] = {}
        self._bodies: dict[bytes, tuple[Body, ...]] = {}
        self._atoms: dict[str, Fluent] = {}

    def _state(self, data: Any) -> frozenset[Fluent]:
        data = _as_bytes(data)
        found = self._states.get(data)
        if found is None:
            found = self._states[data] = unpack_atoms(data, self._atoms)
        return found

    def _body_list(self, data: Any) -> tuple[Body, ...]:
        data = _as_bytes(data)
        found = self._bodies.get(data)
        if found is None:
            found = self._bodies[data] = unpack_bodies(data)
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
