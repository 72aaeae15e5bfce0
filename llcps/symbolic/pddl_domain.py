"""Reading a PDDL domain into plain data, and the robot's naive domain.

The `pddl` library's domain objects become the sorted tuples a knowledge base is
made of (types with their parents, typed constants, predicate signatures), in one
place, so that the knowledge base and the learner of operators read the same
domain the same way. The naive domain is the package's ``pddl/domain.pddl``: the
robot's first knowledge of its four actions, before it learned anything.
"""

from __future__ import annotations

import functools
from importlib import resources

from lark.exceptions import LarkError
from pddl.core import Domain
from pddl.exceptions import PDDLValidationError

from llcps.errors import LlcpsError
from llcps.symbolic.pddl_text import parse_domain_text


def _parse_error(what: str, exc: Exception) -> LlcpsError:
    first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return LlcpsError(f"cannot read the PDDL {what}: {first_line}", hint="check the PDDL syntax and requirements")


def parse_domain(text: str) -> Domain:
    """Parse a PDDL domain with the `pddl` library, turning its errors into one project error."""
    try:
        return parse_domain_text(text)
    except (LarkError, PDDLValidationError, ValueError, AssertionError) as exc:
        raise _parse_error("domain", exc) from exc


def type_parents(domain: Domain) -> tuple[tuple[str, str | None], ...]:
    """Every type with its parent, implicit ``- object`` roots included, sorted."""
    parents: dict[str, str | None] = {str(t): (str(p) if p is not None else None) for t, p in domain.types.items()}
    for p in list(parents.values()):
        if p is not None and p != "object":
            parents.setdefault(p, None)
    parents.pop("object", None)
    return tuple(sorted(parents.items()))


def constant_types(domain: Domain) -> tuple[tuple[str, str], ...]:
    """Every constant with its type (``object`` when untyped), sorted."""
    return tuple(sorted((str(c.name), str(c.type_tag) if c.type_tag else "object") for c in domain.constants))


def predicate_signatures(domain: Domain) -> tuple[tuple[str, tuple[tuple[str, str], ...]], ...]:
    """Every predicate with its typed variables (``?name``, type), sorted."""
    return tuple(
        sorted(
            (str(p.name), tuple((f"?{t.name}", str(sorted(t.type_tags)[0]) if t.type_tags else "object") for t in p.terms))
            for p in domain.predicates
        )
    )


def default_domain_pddl() -> str:
    """The text of the package's naive domain, comments included."""
    return resources.files("llcps.symbolic").joinpath("pddl/domain.pddl").read_text(encoding="utf-8")


@functools.cache
def _default_domain() -> Domain:
    return parse_domain(default_domain_pddl())


def default_constants() -> dict[str, str]:
    """Constant -> type of the naive domain (what ``KnowledgeBase.default().constants`` gives)."""
    return dict(constant_types(_default_domain()))


@functools.cache
def _default_parents() -> dict[str, str | None]:
    return dict(type_parents(_default_domain()))


def default_is_subtype(kind: str, ancestor: str) -> bool:
    """Whether an object of type ``kind`` may fill a parameter of type ``ancestor`` in the
    naive domain (what ``KnowledgeBase.default().is_subtype`` says)."""
    parents = _default_parents()
    seen: set[str] = set()
    current: str | None = kind
    while current is not None and current not in seen:
        if current == ancestor:
            return True
        seen.add(current)
        current = parents.get(current)
    return ancestor == "object"


def clear_caches() -> None:
    _default_domain.cache_clear()
    _default_parents.cache_clear()


def default_predicates() -> dict[str, int]:
    """Predicate -> arity of the naive domain (what ``KnowledgeBase.default().predicates`` gives)."""
    return {name: len(params) for name, params in predicate_signatures(_default_domain())}
