"""K' of a branch: the naive K plus everything the branch has learned."""

from __future__ import annotations

from llcps.errors import LlcpsError, StoreError
from llcps.store import Store
from llcps.symbolic.knowledge import KnowledgeBase


def load_knowledge(store: Store, branch: str) -> KnowledgeBase:
    """The default K plus every learned operator (and refinement) ``branch`` sees, oldest first.

    Raises:
        StoreError: a stored operator does not describe an operator (the message names it).
    """
    kb = KnowledgeBase.default()
    for record in sorted(store.visible_operators(branch), key=lambda r: r.id):
        try:
            kb = kb.apply_learned(record.definition)
        except (LlcpsError, ValueError, TypeError, KeyError, AttributeError, IndexError, RecursionError) as exc:
            detail = exc.message if isinstance(exc, LlcpsError) else f"{type(exc).__name__}: {exc}"
            raise StoreError(
                f"stored operator {record.id} ({record.name!r}) is malformed: {detail}",
                hint="the row was changed outside llcps; delete it or restore the database from a copy",
            ) from None
    return kb
