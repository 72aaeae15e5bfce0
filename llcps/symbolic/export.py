"""K' and a task as plain PDDL that other planners accept.

The planner of :mod:`llcps.symbolic.planner` reads more than K's PDDL says: experience
costs a step in the context it would run in, and leaves an operator out of a context
where it only failed. The export writes what of that PDDL can carry, for any planner
with STRIPS, typing, negative and disjunctive preconditions, equality and (optionally)
action costs (Fast Downward, through unified-planning, in the tests):

- **costs** (``"integer"``): each operator's cost by experience over every context, times
  :data:`COST_SCALE` and rounded, as planners such as Fast Downward take integer costs
  only. Plans keep their order unless two differ by less than 1/:data:`COST_SCALE`.
  ``"none"`` drops costs altogether (no ``:functions``, no ``:metric``), for planners
  without action costs.
- **inequalities**: a learned operator's ``(not (= ?a ?b))`` (see
  :meth:`~llcps.symbolic.operators.LearnedOperator.distinct`), as in K.
- **context bans**: where an operator has failed in a context and never worked there
  (:meth:`~llcps.symbolic.knowledge_base.KnowledgeBase.allowed`), a disjunctive
  precondition that the step's context is not that one: some fact of it is false, or
  some other fact over the step's arguments holds.

What PDDL cannot carry, the cost of an operator in one context where experience there
differs from its cost over every context, is listed in a comment at the top of the file.
Nor does it carry the planner's stricter ban in the states a plan predicts (a context
never seen that contains one where the operator only failed): a planner reading the
export may plan such a step where llcps's planner does not.
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import Callable, Sequence

from pddl.logic.base import Formula, Not, Or

from llcps.domain import Fluent, fluent
from llcps.errors import LlcpsError
from llcps.symbolic.experience import Context, experience_cost
from llcps.symbolic.knowledge_base import REQUIREMENTS, KnowledgeBase
from llcps.symbolic.lifted import Operator, operator_to_pddl, sort_fluents
from llcps.symbolic.task import Task

#: Experience costs are multiplied by this and rounded to integers in the export.
COST_SCALE = 1000

#: How the export writes costs: scaled integers, or none at all.
COSTS: tuple[str, ...] = ("integer", "none")


def integer_cost(cost: float) -> int:
    """An experience cost as the export writes it: ``round(cost * COST_SCALE)``."""
    return round(cost * COST_SCALE)


def _check_costs(costs: str) -> None:
    if costs not in COSTS:
        raise LlcpsError(f"unknown cost compilation {costs!r}", hint=f"choose one of {', '.join(COSTS)}")


def bans(kb: KnowledgeBase) -> dict[str, list[Context]]:
    """Operator name (lower case) -> the contexts it may not run in (it failed there, never worked)."""
    out: dict[str, list[Context]] = {}
    for name, context, successes, failures in kb.experience.entries:
        if failures and not successes:
            out.setdefault(name, []).append(frozenset(context))
    return out


def context_atoms(kb: KnowledgeBase, op: Operator) -> list[Fluent]:
    """Every fact a context of ``op``'s steps may hold: each predicate of K over the
    operator's variables and K's constants, at least one variable, one spelling per fact."""
    terms = [*op.variables, *sorted(kb.constants)]
    atoms: set[Fluent] = set()
    for predicate, arity in kb.predicates.items():
        for args in itertools.product(terms, repeat=arity):
            if any(t in op.variables for t in args):
                atoms.add(fluent(predicate, *args))
    return sort_fluents(atoms)


def _ban_conditions(kb: KnowledgeBase, op: Operator, contexts: Sequence[Context]) -> Callable[[Callable[[Fluent], Formula]], list[Formula]]:
    possible = context_atoms(kb, op)

    def conditions(atom: Callable[[Fluent], Formula]) -> list[Formula]:
        out: list[Formula] = []
        for context in sorted(contexts, key=sort_fluents):
            held = sort_fluents(context)
            others = [a for a in possible if a not in context]
            out.append(Or(*[Not(atom(a)) for a in held], *[atom(a) for a in others]))
        return out

    return conditions


def context_costs(kb: KnowledgeBase) -> list[tuple[str, Context, float, float]]:
    """``(operator, context, cost there, cost over every context)`` wherever experience in
    one context costs a step differently from the operator's cost over every context
    (what the export cannot write), for the contexts the operator is allowed in."""
    out = []
    for name, context, successes, failures in kb.experience.entries:
        if failures and not successes:
            continue  # banned there, which the export writes
        here = experience_cost(kb.nominal_cost(name), successes, failures)
        overall = kb.cost(name)
        if here != overall:
            out.append((name, frozenset(context), here, overall))
    return out


def _atoms_text(atoms: Context) -> str:
    return "{" + " ".join("(" + " ".join(a) + ")" for a in sort_fluents(atoms)) + "}"


def _header(kb: KnowledgeBase, costs: str) -> list[str]:
    lines = [f"; Knowledge base {kb.name} exported by llcps."]
    if costs == "integer":
        lines.append(f"; Costs: each operator's cost by experience over every context x {COST_SCALE}, rounded.")
    else:
        lines.append("; Costs: none (a cost-free compilation: any plan is as good as another).")
    banned = bans(kb)
    if banned:
        lines.append("; Contexts an operator failed in and never worked in are excluded by disjunctive preconditions.")
    unexpressed = context_costs(kb) if costs == "integer" else []
    if unexpressed:
        lines.append("; Not expressed: llcps costs a step by experience in the context it runs in;")
        lines.append("; this file costs every step at its operator's cost over every context. Context costs:")
        for name, context, here, overall in unexpressed:
            lines.append(f";   {name} in {_atoms_text(context)}: {integer_cost(here)} (file: {integer_cost(overall)})")
    return lines


def export_domain(kb: KnowledgeBase, *, costs: str = "integer") -> str:
    """K' as plain PDDL domain text (see the module docstring).

    Raises:
        LlcpsError: ``costs`` is not one of :data:`COSTS`.
    """
    _check_costs(costs)
    constants = kb.constants
    banned = bans(kb)
    actions = []
    for op in kb.operators():
        if costs == "integer":
            op = replace(op, cost=integer_cost(op.cost))
        contexts = banned.get(op.name.lower(), [])
        extra = _ban_conditions(kb, op, contexts) if contexts else None
        actions.append(operator_to_pddl(op, constants, costs=costs == "integer", extra_precondition=extra))
    requirements = [r for r in REQUIREMENTS if costs == "integer" or r != "action-costs"]
    if banned:
        requirements.append("disjunctive-preconditions")
    domain = kb.to_domain(actions=actions, requirements=requirements)
    return "\n".join(_header(kb, costs)) + "\n" + str(domain) + "\n"


def export_problem(kb: KnowledgeBase, task: Task, *, costs: str = "integer") -> str:
    """The task as a plain PDDL problem for :func:`export_domain`'s domain.

    Raises:
        LlcpsError: ``costs`` is not one of :data:`COSTS`, or the task does not fit K.
    """
    _check_costs(costs)
    requirements = [r for r in REQUIREMENTS if costs == "integer" or r != "action-costs"]
    domain = kb.to_domain(actions=[], requirements=requirements)
    problem = task.to_problem(kb, domain=domain, costs=costs == "integer")
    return f"; Task {task.name} for the knowledge base {kb.name}, exported by llcps.\n" + str(problem) + "\n"
