"""A scenario's goal as PDDL atoms: ``(in cube bucket)`` must hold, ``(not (in ball cup))``
must not. The one parser of goal text, for scenario files and for goals read back
from the store."""

from __future__ import annotations

import re
from functools import lru_cache
from typing import Iterable

from llcps.domain import Fluent, fluent, format_fluent
from llcps.symbolic.pddl_domain import default_predicates

_NEGATED = re.compile(r"^\(\s*not\s*\((?P<atom>[^()]*)\)\s*\)$")
_ATOM = re.compile(r"^\((?P<atom>[^()]*)\)$")


@lru_cache(maxsize=1)
def predicate_arities() -> dict[str, int]:
    """The predicates of K's domain and their arities (the goal may use any of them)."""
    return default_predicates()


def parse_atom(text: str, names: Iterable[str]) -> tuple[bool, Fluent]:
    """One goal atom: (holds?, fluent).

    Args:
        text: ``(pred a b)`` or ``(not (pred a b))``.
        names: the names an argument may take (entities, fixtures, ``table``).

    Raises:
        ValueError: with the reason, for the caller to place in its file.
    """
    if not isinstance(text, str):
        raise ValueError(f"must be a PDDL atom such as \"(in cube bucket)\", got {text!r}")
    stripped = text.strip()
    negated = _NEGATED.match(stripped)
    match = negated or _ATOM.match(stripped)
    if match is None:
        raise ValueError(f"{text!r} is not an atom: write \"(predicate arg ...)\" or \"(not (predicate arg ...))\"")
    predicate, *arguments = match["atom"].split()
    arities = predicate_arities()
    if predicate not in arities:
        raise ValueError(f"unknown predicate {predicate!r} in {text!r}: K's domain has {', '.join(sorted(arities))}")
    if len(arguments) != arities[predicate]:
        raise ValueError(f"{predicate} takes {arities[predicate]} argument(s), {text!r} gives {len(arguments)}")
    known = set(names)
    for argument in arguments:
        if argument not in known:
            raise ValueError(f"{text!r} names {argument!r}, which is not in the scene (it has {', '.join(sorted(known))})")
    return negated is None, fluent(predicate, *arguments)


def parse_goal(atoms: Iterable[str], names: Iterable[str]) -> tuple[frozenset[Fluent], frozenset[Fluent]]:
    """Goal atoms as (fluents that must hold, fluents that must not).

    Raises:
        ValueError: an atom is malformed, or contradicts another (it and its negation).
    """
    known = tuple(names)
    positive: set[Fluent] = set()
    negative: set[Fluent] = set()
    for text in atoms:
        holds, atom = parse_atom(text, known)
        if atom in (negative if holds else positive):
            raise ValueError(f"{text!r} contradicts another atom of the goal: an atom and its negation cannot both hold")
        (positive if holds else negative).add(atom)
    return frozenset(positive), frozenset(negative)


def goal_text(positive: Iterable[Fluent], negative: Iterable[Fluent]) -> list[str]:
    """The goal as atoms, the way a scenario file writes it (sorted)."""
    return [format_fluent(a) for a in sorted(positive)] + [f"(not {format_fluent(a)})" for a in sorted(negative)]


__all__ = ["goal_text", "parse_atom", "parse_goal", "predicate_arities"]
