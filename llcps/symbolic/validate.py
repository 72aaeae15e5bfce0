"""A plan validator independent of the planner.

It reads the domain and problem *text* with the `pddl` library and replays the plan
under its own reading of PDDL (STRIPS with typing, negative preconditions, equality and
action costs): every step must name a domain action with the right number of
well-typed objects, its precondition must hold, its effects are applied (deletes, then
adds), and the goal must hold at the end. It shares nothing with the planner or the
knowledge base but the PDDL reader, so a plan that passes here is right by the PDDL
text, not by the planner's own bookkeeping. PDDL names are case-insensitive;
everything is compared in lower case.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

from lark.exceptions import LarkError
from pddl.action import Action
from pddl.exceptions import PDDLValidationError
from pddl.logic.base import And, Formula, Imply, Not, Or
from pddl.logic.functions import EqualTo as NumericEqualTo
from pddl.logic.functions import Increase, NumericFunction, NumericValue
from pddl.logic.predicates import EqualTo, Predicate
from pddl.logic.terms import Term, Variable

from llcps.symbolic.pddl_text import parse_domain_text, parse_problem_text

Atom = tuple[str, ...]


@dataclass(frozen=True)
class ValidationResult:
    """The verdict on a plan.

    Attributes:
        ok: every step applies and the goal holds at the end.
        failing_step: index of the first step that is malformed or not applicable, or
            None when all steps applied (then ``ok`` says whether the goal holds).
        reason: why the plan fails ("" when it is valid).
        cost: the plan's total cost up to where the replay stopped.
    """

    ok: bool
    failing_step: int | None
    reason: str
    cost: float = 0.0

    def __bool__(self) -> bool:
        return self.ok


class _Unsupported(Exception):
    pass


def _name(term: Term, binding: Mapping[str, str]) -> str:
    if isinstance(term, Variable):
        return binding[str(term.name).lower()]
    return str(term.name).lower()


def _atom(predicate: Predicate, binding: Mapping[str, str]) -> Atom:
    return (str(predicate.name).lower(), *(_name(t, binding) for t in predicate.terms))


def _holds(formula: Formula | None, state: set[Atom], binding: Mapping[str, str]) -> bool:
    if formula is None:
        return True
    if isinstance(formula, Predicate):
        return _atom(formula, binding) in state
    if isinstance(formula, EqualTo):
        return _name(formula.left, binding) == _name(formula.right, binding)
    if isinstance(formula, Not):
        return not _holds(formula.argument, state, binding)
    if isinstance(formula, And):
        return all(_holds(f, state, binding) for f in formula.operands)
    if isinstance(formula, Or):
        return any(_holds(f, state, binding) for f in formula.operands)
    if isinstance(formula, Imply):
        *premises, conclusion = formula.operands
        return not all(_holds(f, state, binding) for f in premises) or _holds(conclusion, state, binding)
    raise _Unsupported(f"unsupported condition {formula}")


def _effects(formula: Formula | None, binding: Mapping[str, str]) -> tuple[set[Atom], set[Atom], float]:
    adds: set[Atom] = set()
    deletes: set[Atom] = set()
    cost = 0.0
    parts = [] if formula is None else list(formula.operands) if isinstance(formula, And) else [formula]
    for part in parts:
        if isinstance(part, Predicate):
            adds.add(_atom(part, binding))
        elif isinstance(part, Not) and isinstance(part.argument, Predicate):
            deletes.add(_atom(part.argument, binding))
        elif (
            isinstance(part, Increase)
            and isinstance(part.operands[0], NumericFunction)
            and str(part.operands[0].name).lower() == "total-cost"
            and isinstance(part.operands[1], NumericValue)
        ):
            cost += float(part.operands[1].value)
        else:
            raise _Unsupported(f"unsupported effect {part}")
    return adds, deletes, cost


def _is_a(kind: str, wanted: set[str], parents: Mapping[str, str | None]) -> bool:
    seen: set[str] = set()
    current: str | None = kind
    while current is not None and current not in seen:
        if current in wanted:
            return True
        seen.add(current)
        current = parents.get(current)
    return "object" in wanted


def validate(domain_pddl: str, problem_pddl: str, plan: Sequence[tuple[str, Sequence[str]]]) -> ValidationResult:
    """Replay ``plan`` on the problem and say whether it reaches the goal.

    Args:
        domain_pddl: the domain text.
        problem_pddl: the problem text.
        plan: steps as ``(action name, (object, ...))``.
    """
    try:
        domain = parse_domain_text(domain_pddl)
        problem = parse_problem_text(problem_pddl)
    except (LarkError, PDDLValidationError, ValueError, AssertionError) as exc:
        return ValidationResult(False, None, f"cannot parse: {str(exc).strip().splitlines()[0] if str(exc).strip() else exc!r}")
    if str(problem.domain_name).lower() != str(domain.name).lower():
        return ValidationResult(False, None, f"problem is for domain {problem.domain_name}, not {domain.name}")

    parents = {str(t).lower(): (str(p).lower() if p is not None else None) for t, p in domain.types.items()}
    objects: dict[str, str] = {}
    for const in (*domain.constants, *problem.objects):
        objects[str(const.name).lower()] = str(const.type_tag).lower() if const.type_tag else "object"
    actions: dict[str, Action] = {str(a.name).lower(): a for a in domain.actions}

    state: set[Atom] = set()
    cost = 0.0
    for fact in problem.init:
        if isinstance(fact, Predicate):
            state.add(_atom(fact, {}))
        elif isinstance(fact, NumericEqualTo) and isinstance(fact.operands[1], NumericValue):
            cost = float(fact.operands[1].value)
        else:
            return ValidationResult(False, None, f"unsupported initial fact {fact}")

    for index, (action_name, args) in enumerate(plan):
        label = "(" + " ".join((action_name, *args)) + ")"
        action = actions.get(action_name.lower())
        if action is None:
            return ValidationResult(False, index, f"step {index} {label}: no action {action_name} in the domain", cost)
        params = list(action.parameters)
        if len(args) != len(params):
            return ValidationResult(False, index, f"step {index} {label}: {action_name} takes {len(params)} argument(s)", cost)
        binding: dict[str, str] = {}
        for param, arg in zip(params, args):
            arg = arg.lower()
            if arg not in objects:
                return ValidationResult(False, index, f"step {index} {label}: unknown object {arg}", cost)
            wanted = {str(t).lower() for t in param.type_tags} or {"object"}
            if not _is_a(objects[arg], wanted, parents):
                return ValidationResult(
                    False, index, f"step {index} {label}: {arg} is a {objects[arg]}, not a {' or '.join(sorted(wanted))}", cost
                )
            binding[str(param.name).lower()] = arg
        try:
            if not _holds(action.precondition, state, binding):
                return ValidationResult(False, index, f"step {index} {label}: precondition {action.precondition} does not hold", cost)
            adds, deletes, step_cost = _effects(action.effect, binding)
        except _Unsupported as exc:
            return ValidationResult(False, index, f"step {index} {label}: {exc}", cost)
        state = (state - deletes) | adds
        cost += step_cost

    try:
        reached = _holds(problem.goal, state, {})
    except _Unsupported as exc:
        return ValidationResult(False, None, f"goal: {exc}", cost)
    if not reached:
        return ValidationResult(False, None, f"the goal {problem.goal} does not hold after the plan", cost)
    return ValidationResult(True, None, "", cost)
