"""K' of a branch: the naive K plus everything the branch has learned."""

from __future__ import annotations

from llcps.store import Store
from llcps.symbolic.knowledge import KnowledgeBase


def load_knowledge(store: Store, branch: str) -> KnowledgeBase:
    """The default K plus every learned operator (and refinement) ``branch`` sees, oldest first."""
    kb = KnowledgeBase.default()
    for record in sorted(store.visible_operators(branch), key=lambda r: r.id):
        kb = kb.apply_learned(record.definition)
    return kb
