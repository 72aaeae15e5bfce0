"""The robot's naive domain, the package's ``pddl/domain.pddl``: its text and its vocabulary.

The knowledge base K starts from this text (:meth:`llcps.symbolic.knowledge.KnowledgeBase.default`);
a learned operator is written in its constants and predicates
(:func:`llcps.symbolic.operators.learn_operator`) unless told another vocabulary.
"""

from __future__ import annotations

import functools
from importlib import resources
from typing import Mapping

from llcps.symbolic.pddl_text import parse_domain_text


def default_domain_pddl() -> str:
    """The text of the package's naive domain, comments included."""
    return resources.files("llcps.symbolic").joinpath("pddl/domain.pddl").read_text(encoding="utf-8")


@functools.cache
def _vocabulary() -> tuple[frozenset[str], tuple[tuple[str, int], ...]]:
    domain = parse_domain_text(default_domain_pddl())
    constants = frozenset(str(c.name) for c in domain.constants)
    predicates = tuple(sorted((str(p.name), len(p.terms)) for p in domain.predicates))
    return constants, predicates


def default_constants() -> frozenset[str]:
    """The names of the naive domain's constants (``table``)."""
    return _vocabulary()[0]


def default_predicates() -> Mapping[str, int]:
    """Predicate -> arity of the naive domain."""
    return dict(_vocabulary()[1])
