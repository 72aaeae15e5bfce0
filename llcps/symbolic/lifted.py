"""Lifted operators and their ground instances: the unit the planner searches with,
the monitor checks against and the knowledge base stores.

An operator is written in the planner's own terms (fluent tuples whose variables start
with ``?``), and converted to and from the `pddl` library's objects here, in one place,
so that every PDDL text this package writes or reads goes through the same rules:

- ``touching`` is symmetric. Inside the package a fact has one spelling (see
  :func:`llcps.domain.fluent`); in PDDL, which has no symmetric predicates, every effect
  on ``touching`` asserts both orderings and problems list both orderings in ``:init``,
  so that any PDDL tool reads the same meaning.
- ``(= ?a ?b)`` is a static test on the arguments, never a state fact; it is kept in the
  precondition sets under the predicate name ``=`` and decided at grounding time.
- The cost of an operator is its ``(increase (total-cost) c)`` effect.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

from pddl.action import Action
from pddl.logic.base import And, Formula, Not
from pddl.logic.functions import Increase, NumericFunction, NumericValue
from pddl.logic.predicates import EqualTo, Predicate
from pddl.logic.terms import Constant, Term, Variable

from llcps.domain import ACTION_ARITY, ACTIONS, SYMMETRIC_PREDICATES, ControllerParams, Fluent, State, fluent
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError

#: The predicate name under which (in)equality tests sit in precondition sets.
EQUALITY = "="

#: The numeric fluent that carries action costs.
TOTAL_COST = "total-cost"

#: What a PDDL name may look like (objects, actions, predicates).
PDDL_NAME = re.compile(r"[A-Za-z][-_A-Za-z0-9]*")


def is_variable(term: str) -> bool:
    """Whether a term of a lifted fluent is a parameter variable (``?o``) or a constant."""
    return term.startswith("?")


def substitute(atom: Fluent, binding: Mapping[str, str]) -> Fluent:
    """Replace the terms of a fluent that the binding names, and re-canonicalise it."""
    return fluent(atom[0], *(binding.get(term, term) for term in atom[1:]))


def sort_fluents(atoms: Iterable[Fluent]) -> list[Fluent]:
    """A deterministic order for printing and iterating over fluents."""
    return sorted(atoms)


@dataclass(frozen=True)
class Controller:
    """Which action controller executes an operator, and with what.

    Attributes:
        action: the controller, one of :data:`llcps.domain.ACTIONS`.
        arguments: the parameter variables passed to the controller as its physical
            arguments, in controller order.
        params: fixed controller settings (a learned operator), or None when the agent
            chooses nominal settings (the naive actions of K).
        toward: a parameter variable the controller aims at without touching it, e.g.
            ``push(?o)`` is oriented toward ``?c``; None when there is no such target.
    """

    action: str
    arguments: tuple[str, ...]
    params: ControllerParams | None = None
    toward: str | None = None

    def __post_init__(self) -> None:
        if self.action not in ACTIONS:
            raise ValueError(f"unknown controller {self.action!r}; expected one of {ACTIONS}")
        if len(self.arguments) != ACTION_ARITY[self.action]:
            raise ValueError(f"controller {self.action} takes {ACTION_ARITY[self.action]} argument(s), got {self.arguments}")

    def bind(self, binding: Mapping[str, str]) -> ControllerCall:
        """Ground the controller's arguments with a parameter binding."""
        return ControllerCall(
            action=self.action,
            arguments=tuple(binding[v] for v in self.arguments),
            params=self.params,
            toward=binding[self.toward] if self.toward is not None else None,
        )


@dataclass(frozen=True)
class ControllerCall:
    """A controller bound to objects: what the executor runs for one plan step."""

    action: str
    arguments: tuple[str, ...]
    params: ControllerParams | None = None
    toward: str | None = None

    def spec(self, nominal: ControllerParams) -> TrialSpec:
        """The trial to execute; fixed (learned) settings win over the nominal ones.

        Args:
            nominal: the settings the agent uses for an action of the naive K.
        """
        return TrialSpec(action=self.action, arguments=self.arguments, params=self.params or nominal)


@dataclass(frozen=True)
class GroundAction:
    """One step of a plan: an operator applied to objects.

    Attributes:
        name: the operator's name (``push``, ``remove_from_container``, a learned one).
        args: the objects bound to the operator's parameters, in order.
        preconditions: fluents that must hold before the step.
        add: fluents the step is expected to make true.
        delete: fluents the step is expected to make false.
        cost: the step's cost in the plan metric.
        negative_preconditions: fluents that must not hold before the step.
        controller: the controller call that executes the step.
    """

    name: str
    args: tuple[str, ...]
    preconditions: frozenset[Fluent]
    add: frozenset[Fluent]
    delete: frozenset[Fluent]
    cost: float
    negative_preconditions: frozenset[Fluent] = frozenset()
    controller: ControllerCall | None = None

    def applicable(self, state: State) -> bool:
        """Whether every precondition holds in ``state``."""
        return self.preconditions <= state and self.negative_preconditions.isdisjoint(state)

    def apply(self, state: State) -> State:
        """The successor state (STRIPS semantics: deletes first, then adds)."""
        return (state - self.delete) | self.add

    @property
    def label(self) -> str:
        """The step as PDDL prints it: ``(push cube bucket)``."""
        return "(" + " ".join((self.name, *self.args)) + ")"

    def __str__(self) -> str:
        return self.label


@dataclass(frozen=True)
class Operator:
    """A lifted action of the knowledge base K.

    Attributes:
        name: a PDDL name, unique in the knowledge base.
        parameters: ``(variable, type)`` pairs; variables start with ``?``.
        preconditions: lifted fluents that must hold (may include ``("=", ?a, ?b)``).
        negative_preconditions: lifted fluents that must not hold (may include ``=``).
        add: lifted fluents the operator makes true.
        delete: lifted fluents the operator makes false.
        cost: the operator's cost in the plan metric.
        controller: how the operator is executed.
    """

    name: str
    parameters: tuple[tuple[str, str], ...]
    preconditions: frozenset[Fluent]
    negative_preconditions: frozenset[Fluent]
    add: frozenset[Fluent]
    delete: frozenset[Fluent]
    cost: float
    controller: Controller

    def __post_init__(self) -> None:
        if not PDDL_NAME.fullmatch(self.name):
            raise ValueError(f"operator name {self.name!r} is not a PDDL name")
        variables = [v for v, _ in self.parameters]
        if len(set(variables)) != len(variables) or not all(is_variable(v) for v in variables):
            raise ValueError(f"operator {self.name} has malformed parameters {self.parameters}")
        known = set(variables)
        for atom in (*self.preconditions, *self.negative_preconditions, *self.add, *self.delete):
            free = {t for t in atom[1:] if is_variable(t)} - known
            if free:
                raise ValueError(f"operator {self.name} uses undeclared variable(s) {sorted(free)} in {atom}")
        controller_vars = set(self.controller.arguments) | ({self.controller.toward} - {None})
        if not controller_vars <= known:
            raise ValueError(f"operator {self.name}: controller uses undeclared variable(s) {sorted(controller_vars - known)}")
        if self.cost < 0:
            raise ValueError(f"operator {self.name} has a negative cost {self.cost}")

    @property
    def variables(self) -> tuple[str, ...]:
        return tuple(v for v, _ in self.parameters)

    def ground(self, args: Sequence[str]) -> GroundAction | None:
        """Bind the parameters to objects.

        Returns:
            The ground action, or None when a static ``=`` test rules the binding out.
        """
        if len(args) != len(self.parameters):
            raise ValueError(f"{self.name} takes {len(self.parameters)} argument(s), got {tuple(args)}")
        binding = dict(zip(self.variables, args))
        for negated, atoms in ((False, self.preconditions), (True, self.negative_preconditions)):
            for atom in atoms:
                if atom[0] == EQUALITY and (binding.get(atom[1], atom[1]) == binding.get(atom[2], atom[2])) == negated:
                    return None

        def bound(atoms: frozenset[Fluent]) -> frozenset[Fluent]:
            return frozenset(substitute(a, binding) for a in atoms if a[0] != EQUALITY)

        return GroundAction(
            name=self.name,
            args=tuple(args),
            preconditions=bound(self.preconditions),
            add=bound(self.add),
            delete=bound(self.delete),
            cost=self.cost,
            negative_preconditions=bound(self.negative_preconditions),
            controller=self.controller.bind(binding),
        )

    def with_preconditions(self, extra: Iterable[Fluent]) -> Operator:
        """The same operator with more positive preconditions (knowledge refinement)."""
        return Operator(
            name=self.name,
            parameters=self.parameters,
            preconditions=self.preconditions | frozenset(fluent(a[0], *a[1:]) for a in extra),
            negative_preconditions=self.negative_preconditions,
            add=self.add,
            delete=self.delete,
            cost=self.cost,
            controller=self.controller,
        )


# --------------------------------------------------------------------------- PDDL


def _number(value: float) -> int | float:
    """Print whole costs as integers (``1`` rather than ``1.0``)."""
    return int(value) if float(value).is_integer() else float(value)


def operator_to_pddl(
    op: Operator,
    constant_types: Mapping[str, str] | None = None,
    *,
    costs: bool = True,
    extra_precondition: Callable[[Callable[[Fluent], Formula]], Sequence[Formula]] | None = None,
) -> Action:
    """Render an operator as a `pddl` library action.

    Args:
        op: the operator.
        constant_types: types of the domain constants the operator mentions (for type tags).
        costs: whether the effect increases ``total-cost`` (False: a cost-free action).
        extra_precondition: more conjuncts for the precondition, built from the operator's
            lifted fluents with the function it is given (used by the PDDL export).
    """
    constant_types = constant_types or {}
    variables = {v: Variable(v[1:], [t]) for v, t in op.parameters}

    def term(name: str) -> Term:
        if is_variable(name):
            return variables[name]
        return Constant(name, constant_types.get(name))

    def atom(a: Fluent) -> Formula:
        if a[0] == EQUALITY:
            return EqualTo(term(a[1]), term(a[2]))
        return Predicate(a[0], *(term(t) for t in a[1:]))

    def both_orderings(atoms: Iterable[Fluent]) -> list[Fluent]:
        out: set[Fluent] = set()
        for a in atoms:
            out.add(a)
            if a[0] in SYMMETRIC_PREDICATES:
                out.add((a[0], *reversed(a[1:])))
        return sort_fluents(out)

    precondition = [atom(a) for a in sort_fluents(op.preconditions)]
    precondition += [Not(atom(a)) for a in sort_fluents(op.negative_preconditions)]
    if extra_precondition is not None:
        precondition += extra_precondition(atom)
    effect: list[Formula] = [atom(a) for a in both_orderings(op.add)]
    effect += [Not(atom(a)) for a in both_orderings(op.delete)]
    if costs:
        effect.append(Increase(NumericFunction(TOTAL_COST), NumericValue(_number(op.cost))))
    return Action(
        op.name,
        parameters=[variables[v] for v, _ in op.parameters],
        precondition=And(*precondition) if precondition else None,
        effect=And(*effect),
    )


def _unsupported(action: str, what: object) -> LlcpsError:
    return LlcpsError(
        f"action {action}: unsupported PDDL construct {what}",
        hint="the knowledge base uses STRIPS with typing, negative preconditions, equality and action costs",
    )


def _term_name(term: Term) -> str:
    return f"?{term.name}" if isinstance(term, Variable) else str(term.name)


def _literals(formula: Formula | None) -> tuple[set[Fluent], set[Fluent], list[Formula]]:
    """Split a conjunction of literals into positive atoms, negative atoms and the rest."""
    if formula is None:
        return set(), set(), []
    parts = list(formula.operands) if isinstance(formula, And) else [formula]
    positive: set[Fluent] = set()
    negative: set[Fluent] = set()
    rest: list[Formula] = []
    for part in parts:
        target, negated = (part.argument, True) if isinstance(part, Not) else (part, False)
        if isinstance(target, Predicate):
            atom = fluent(str(target.name), *(_term_name(t) for t in target.terms))
        elif isinstance(target, EqualTo):
            atom = (EQUALITY, _term_name(target.left), _term_name(target.right))
        else:
            rest.append(part)
            continue
        (negative if negated else positive).add(atom)
    return positive, negative, rest


def operator_parts_from_pddl(action: Action) -> dict[str, object]:
    """Read a `pddl` library action into the fields of an :class:`Operator` (no controller).

    Raises:
        LlcpsError: the action uses something other than a conjunction of literals,
            or its cost is not a single constant ``(increase (total-cost) c)``.
    """
    name = str(action.name)
    parameters = []
    for p in action.parameters:
        tags = sorted(map(str, p.type_tags))
        if len(tags) > 1:
            raise _unsupported(name, f"(either {' '.join(tags)})")
        parameters.append((f"?{p.name}", tags[0] if tags else "object"))
    pre_pos, pre_neg, rest = _literals(action.precondition)
    if rest:
        raise _unsupported(name, rest[0])
    add, delete, rest = _literals(action.effect)
    if any(a[0] == EQUALITY for a in add | delete):
        raise _unsupported(name, "an equality in an effect")
    cost = 0.0
    for part in rest:
        if (
            isinstance(part, Increase)
            and isinstance(part.operands[0], NumericFunction)
            and str(part.operands[0].name) == TOTAL_COST
            and isinstance(part.operands[1], NumericValue)
        ):
            cost += float(part.operands[1].value)
        else:
            raise _unsupported(name, part)
    return dict(
        name=name,
        parameters=tuple(parameters),
        preconditions=frozenset(pre_pos),
        negative_preconditions=frozenset(pre_neg),
        add=frozenset(add),
        delete=frozenset(delete),
        cost=cost,
    )
