"""K' of a branch: the naive K plus everything the branch has learned, costed by its experience."""

from __future__ import annotations

from llcps.errors import LlcpsError, StoreError
from llcps.store import Store
from llcps.symbolic.experience import Experience
from llcps.symbolic.knowledge_base import KnowledgeBase


def load_knowledge(store: Store, branch: str) -> KnowledgeBase:
    """The default K plus every learned operator (and refinement) ``branch`` sees, oldest
    first, costed by the operator executions ``branch`` sees.

    Raises:
        StoreError: a stored operator does not describe an operator, or a stored
            execution's context is malformed (the message names the row).
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
    return kb.with_experience(load_experience(store, branch))


def load_experience(store: Store, branch: str) -> Experience:
    """The operator executions ``branch`` sees, counted per operator and context."""
    return Experience.from_counts((c.operator, c.context, c.successes, c.failures) for c in store.operator_experience(branch))
