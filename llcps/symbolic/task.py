"""Tasks T = (K, s0, sg) without K: the objects, the perceived initial state and the
goal, checked against a knowledge base and written as a PDDL problem for its domain."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

from pddl.core import Domain, Problem
from pddl.logic.base import And, Formula, Not
from pddl.logic.functions import EqualTo as NumericEqualTo
from pddl.logic.functions import Metric, NumericFunction, NumericValue
from pddl.logic.predicates import Predicate
from pddl.logic.terms import Constant

from llcps.domain import SYMMETRIC_PREDICATES, Fluent, State, fluent
from llcps.errors import LlcpsError, UnknownNameError
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.pddl_domain import default_constants
from llcps.symbolic.lifted import PDDL_NAME, TOTAL_COST, sort_fluents


def _symmetric_closure(state: Iterable[Fluent]) -> list[Fluent]:
    out: set[Fluent] = set()
    for atom in state:
        out.add(atom)
        if atom[0] in SYMMETRIC_PREDICATES:
            out.add((atom[0], *reversed(atom[1:])))
    return sort_fluents(out)


@dataclass(frozen=True)
class Task:
    """T = (K, s0, sg) without K: the objects, the perceived initial state and the goal.

    Attributes:
        objects: object -> type (``item``, ``container``, ``surface``, ``entity``).
        init: s0, the fluents that hold.
        goal_pos: fluents the goal requires.
        goal_neg: fluents the goal forbids.
        name: the PDDL problem name.
    """

    objects: Mapping[str, str]
    init: State
    goal_pos: frozenset[Fluent] = frozenset()
    goal_neg: frozenset[Fluent] = frozenset()
    name: str = "task"

    def __post_init__(self) -> None:
        object.__setattr__(self, "objects", dict(self.objects))
        for attr in ("init", "goal_pos", "goal_neg"):
            object.__setattr__(self, attr, frozenset(fluent(a[0], *a[1:]) for a in getattr(self, attr)))

    @classmethod
    def from_scene(
        cls,
        *,
        entities: Mapping[str, str],
        fixtures: Iterable[str],
        init: State,
        goal_pos: Iterable[Fluent] = (),
        goal_neg: Iterable[Fluent] = (),
    ) -> Task:
        """The task of a scene: its entities and fixtures as PDDL objects, typed for K.

        Args:
            entities: entity name -> kind (``object`` becomes an ``item``, any other kind
                a ``container``).
            fixtures: the scene's fixtures; each is a ``surface``, but those the
                domain declares as constants (the table) are no task objects.
            init: the perceived state.
            goal_pos, goal_neg: the goal's fluents that must hold, and must not.
        """
        objects = {name: ("item" if kind == "object" else "container") for name, kind in entities.items()}
        constants = default_constants()
        objects.update({name: "surface" for name in fixtures if name not in constants})
        return cls(objects=objects, init=init, goal_pos=frozenset(goal_pos), goal_neg=frozenset(goal_neg))

    def satisfied_by(self, state: State) -> bool:
        """Whether ``state`` is a goal state."""
        return self.goal_pos <= state and self.goal_neg.isdisjoint(state)

    def all_objects(self, kb: KnowledgeBase) -> dict[str, str]:
        """The task's objects together with K's constants (object -> type)."""
        return {**self.objects, **kb.constants}

    def check(self, kb: KnowledgeBase) -> None:
        """Check the task against K: known names, types and predicate arities.

        Raises:
            LlcpsError: naming the first problem found.
        """
        constants = kb.constants
        types = kb.known_types()
        lower: dict[str, str] = {}
        for obj, kind in self.objects.items():
            if not PDDL_NAME.fullmatch(obj):
                raise LlcpsError(f"object name {obj!r} is not a PDDL name", hint="use letters, digits, '-' and '_', starting with a letter")
            if kind not in types:
                raise LlcpsError(f"object {obj} has unknown type {kind!r}", hint=f"known types: {', '.join(sorted(types))}")
            if obj in constants and constants[obj] != kind:
                raise LlcpsError(f"object {obj} is typed {kind} but is the domain constant of type {constants[obj]}")
            if obj.lower() in lower:
                raise LlcpsError(f"objects {lower[obj.lower()]} and {obj} differ only by case", hint="PDDL names are case-insensitive")
            lower[obj.lower()] = obj
        everything = self.all_objects(kb)
        arities = kb.predicates
        for what, atoms in (("initial state", self.init), ("goal", self.goal_pos | self.goal_neg)):
            for atom in atoms:
                if atom[0] not in arities:
                    raise UnknownNameError("predicate", atom[0], sorted(arities))
                if len(atom) - 1 != arities[atom[0]]:
                    raise LlcpsError(f"{what}: {atom[0]} takes {arities[atom[0]]} argument(s), got {atom[1:]}")
                unknown = [t for t in atom[1:] if t not in everything]
                if unknown:
                    raise LlcpsError(f"{what}: ({' '.join(atom)}) mentions unknown object(s) {', '.join(unknown)}", hint="list every entity in Task.objects")

    def to_problem(self, kb: KnowledgeBase, *, domain: Domain | None = None, costs: bool = True) -> Problem:
        """T as a `pddl` library problem against K's domain (type-checked by the library).

        Args:
            kb: the knowledge base K.
            domain: K's domain as written (default: :meth:`KnowledgeBase.to_domain`).
            costs: whether the problem sets and minimizes ``total-cost``.
        """
        self.check(kb)
        everything = self.all_objects(kb)
        constants = kb.constants

        def atom(a: Fluent) -> Predicate:
            return Predicate(a[0], *(Constant(t, everything[t]) for t in a[1:]))

        goal: list[Formula] = [atom(a) for a in sort_fluents(self.goal_pos)]
        goal += [Not(atom(a)) for a in sort_fluents(self.goal_neg)]
        init: list[Formula] = [atom(a) for a in _symmetric_closure(self.init)]
        if costs:
            init.append(NumericEqualTo(NumericFunction(TOTAL_COST), NumericValue(0)))
        return Problem(
            self.name,
            domain=kb.to_domain() if domain is None else domain,
            objects=[Constant(o, t) for o, t in sorted(self.objects.items()) if o not in constants],
            init=init,
            goal=And(*goal),
            metric=Metric(NumericFunction(TOTAL_COST), Metric.MINIMIZE) if costs else None,
        )

    def problem_pddl(self, kb: KnowledgeBase) -> str:
        """T as PDDL problem text for K's domain."""
        return str(self.to_problem(kb)) + "\n"
