"""The knowledge base K: a PDDL domain plus learned operators (tasks T are :mod:`llcps.symbolic.task`).

K starts as the package's ``pddl/domain.pddl``: the robot's naive knowledge of its four
actions. Exploration expands it into K' with learned operators
(:meth:`KnowledgeBase.with_operator`) and with preconditions it learned a failed action
needs (:meth:`KnowledgeBase.with_refinement`). A knowledge base is a value: every change
returns a new one, so the K of a branch and its K' can be held side by side.

Operators are costed by experience (:meth:`KnowledgeBase.with_experience`): each step's
plan cost is its operator's nominal cost divided by the Laplace-smoothed rate at which
its executions achieved their effects, in the context the step would run in where it
ran there before (:mod:`llcps.symbolic.experience`). An operator that fails is demoted,
never deleted, and one that keeps working is preferred; so what the robot learns cannot
shadow what worked before without paying for its failures.

All PDDL is read and written with the `pddl` library (AI-Planning).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import Callable, Iterable, Mapping, Sequence

from pddl.action import Action
from pddl.core import Domain
from pddl.exceptions import PDDLValidationError
from pddl.logic.functions import NumericFunction
from pddl.logic.predicates import Predicate
from pddl.logic.terms import Constant, Variable
from pddl.requirements import Requirements

from llcps.domain import ACTION_ARITY, ACTIONS, SYMMETRIC_PREDICATES, Fluent, State, fluent
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError, UnknownNameError
from llcps.symbolic.experience import Context, Experience, step_context
from llcps.symbolic.operators import LearnedOperator, parse_operator_name
from llcps.symbolic.pddl_domain import (
    constant_types,
    default_domain_pddl,
    parse_domain,
    predicate_signatures,
    type_parents,
)
from llcps.symbolic.lifted import (
    TOTAL_COST,
    Controller,
    GroundAction,
    Operator,
    operator_parts_from_pddl,
    is_variable,
    operator_to_pddl,
)

#: The requirements every knowledge base declares.
REQUIREMENTS: tuple[str, ...] = ("strips", "typing", "negative-preconditions", "equality", "action-costs")


def _domain_action_operator(parts: dict[str, object]) -> Operator:
    """A naive action of K: its controller takes the first parameters, and aims at the next one if any."""
    name = str(parts["name"])
    variables = [v for v, _ in parts["parameters"]]  # type: ignore[attr-defined]
    arity = ACTION_ARITY[name]
    if len(variables) < arity:
        raise LlcpsError(f"action {name} needs at least {arity} parameter(s) for its controller, got {len(variables)}")
    toward = variables[arity] if len(variables) > arity else None
    return Operator(**parts, controller=Controller(action=name, arguments=tuple(variables[:arity]), toward=toward))  # type: ignore[arg-type]


@dataclass(frozen=True)
class KnowledgeBase:
    """K: types, constants, predicates, the domain's actions and the learned operators.

    Attributes:
        name: the PDDL domain name.
        type_parents: ``(type, parent)`` pairs; ``parent`` None means ``object``.
        constant_types: ``(constant, type)`` pairs (``table``).
        predicate_signatures: ``(predicate, ((variable, type), ...))`` pairs.
        actions: the domain's actions, as refined so far, at their nominal costs.
        learned: operators learned from exploration, in the order they were learned.
        experience: executions as plan steps, per operator and context; a step's plan
            cost is :meth:`Experience.cost` of its operator's nominal cost. A learned
            operator's nominal cost is that of the action it was learned to replace.
    """

    name: str
    type_parents: tuple[tuple[str, str | None], ...]
    constant_types: tuple[tuple[str, str], ...]
    predicate_signatures: tuple[tuple[str, tuple[tuple[str, str], ...]], ...]
    actions: tuple[Operator, ...]
    learned: tuple[LearnedOperator, ...] = ()
    experience: Experience = Experience()
    _types: dict[str, str | None] = field(init=False, repr=False, compare=False)
    _variables: dict[str, tuple[str, ...]] = field(init=False, repr=False, compare=False)
    _nominal: dict[str, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_types", dict(self.type_parents))
        object.__setattr__(self, "_variables", {op.name.lower(): op.variables for op in (*self.actions, *self.learned)})
        object.__setattr__(self, "_nominal", {})
        names = [op.name.lower() for op in self.operators()]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise LlcpsError(f"duplicate operator name(s) in the knowledge base: {', '.join(duplicates)}")
        known = self.known_types()
        for op in self.operators():
            for var, kind in op.parameters:
                if kind not in known:
                    raise LlcpsError(f"operator {op.name}: parameter {var} has unknown type {kind!r}", hint=f"known types: {', '.join(sorted(known))}")

    # ------------------------------------------------------------------ construction

    @classmethod
    def default(cls) -> KnowledgeBase:
        """The robot's initial, naive K (the package's ``pddl/domain.pddl``)."""
        return _default_kb()

    @classmethod
    def from_pddl(cls, text: str) -> KnowledgeBase:
        """Read K from a PDDL domain; actions named like learned operators become learned operators.

        Raises:
            LlcpsError: the text does not parse, or an action is neither one of the four
                controller actions nor a learned operator.
        """
        domain = parse_domain(text)
        actions: list[Operator] = []
        learned: list[LearnedOperator] = []
        for action in sorted(domain.actions, key=lambda a: str(a.name)):
            parts = operator_parts_from_pddl(action)
            if str(parts["name"]) in ACTIONS:
                actions.append(_domain_action_operator(parts))
            else:
                learned.append(LearnedOperator.from_fields(**parts))  # type: ignore[arg-type]
        learned.sort(key=lambda op: op.name)
        return cls(
            name=str(domain.name),
            type_parents=type_parents(domain),
            constant_types=constant_types(domain),
            predicate_signatures=predicate_signatures(domain),
            actions=tuple(actions),
            learned=tuple(learned),
        )

    def with_operator(self, op: LearnedOperator) -> KnowledgeBase:
        """K' = K plus a learned operator.

        Adding an operator that teaches nothing new (same settings, parameters,
        preconditions and effects as one already known) returns K unchanged; the same
        skill seen to work in another context generalizes the known operator to what both
        contexts share (:meth:`LearnedOperator.generalized`); a different operator with a
        taken name is renamed ``<name>_2``, ``_3``, ...
        """
        for index, known in enumerate(self.learned):
            if op.same_knowledge(known):
                return self
            if op.same_skill(known):
                learned = list(self.learned)
                learned[index] = known.generalized(op)
                return replace(self, learned=tuple(learned))
        taken = {o.name.lower() for o in self.operators()}
        if op.name.lower() in taken:
            parsed = parse_operator_name(op.name)
            base = op.name if parsed is None or parsed[2] == 1 else op.name.rsplit("_", 1)[0]
            n = 2
            while f"{base}_{n}".lower() in taken:
                n += 1
            op = op.renamed(f"{base}_{n}")
        return replace(self, learned=(*self.learned, op))

    def with_refinement(self, action: str, extra_preconditions: Iterable[Fluent]) -> KnowledgeBase:
        """K' in which ``action`` (a domain action or a learned operator) needs more preconditions.

        Args:
            action: the operator's name.
            extra_preconditions: lifted fluents over the operator's parameters.
        """
        extra = frozenset(fluent(a[0], *a[1:]) for a in extra_preconditions)
        op = self.operator(action)
        op.with_preconditions(extra)  # validates the variables
        if any(a.name == op.name for a in self.actions):
            actions = tuple(a.with_preconditions(extra) if a.name == op.name else a for a in self.actions)
            return replace(self, actions=actions)
        learned = tuple(
            replace(o, preconditions=o.preconditions | extra) if o.name == op.name else o for o in self.learned
        )
        return replace(self, learned=learned)

    def apply_learned(self, definition: Mapping[str, object]) -> KnowledgeBase:
        """Replay one stored expansion: ``{"operator": LearnedOperator.to_json(), "refinement": ...}``.

        A refinement (extra preconditions of a domain action, ``{"action": name,
        "preconditions": [[predicate, term, ...], ...]}``) is written by no current llcps;
        stores from versions that learned them keep them.

        Raises:
            LlcpsError: the record is malformed.
        """
        kb = self.with_operator(LearnedOperator.from_json(definition["operator"]))  # type: ignore[arg-type]
        refinement = definition.get("refinement")
        if refinement:
            try:
                action = str(refinement["action"])  # type: ignore[index]
                extra = [tuple(map(str, a)) for a in refinement["preconditions"]]  # type: ignore[index]
            except (KeyError, TypeError) as exc:
                raise LlcpsError(f"malformed refinement record: {exc}", hint="a refinement is {\"action\": name, \"preconditions\": [[predicate, term, ...], ...]}") from exc
            kb = kb.with_refinement(action, extra)
        return kb

    # ------------------------------------------------------------------ reading

    @property
    def constants(self) -> dict[str, str]:
        """Constant -> type."""
        return dict(self.constant_types)

    @property
    def predicates(self) -> dict[str, int]:
        """Predicate -> arity."""
        return {name: len(params) for name, params in self.predicate_signatures}

    def skill(self, op: LearnedOperator) -> LearnedOperator:
        """The learned operator of this K' that holds ``op``'s skill (``op`` itself, renamed
        or generalized by :meth:`with_operator`).

        Raises:
            UnknownNameError: no learned operator has that skill.
        """
        for known in self.learned:
            if known.same_skill(op):
                return known
        raise UnknownNameError("learned operator", op.name, [o.name for o in self.learned])

    def initial(self) -> KnowledgeBase:
        """K as it was before anything was learned: the domain's actions, without the
        learned operators and the experience that costs them."""
        return replace(self, learned=(), experience=Experience())

    def with_experience(self, experience: Experience) -> KnowledgeBase:
        """K with plan costs set by ``experience`` (it replaces any experience K had)."""
        return replace(self, experience=experience)

    def counts(self, name: str) -> tuple[int, int]:
        """(successes, failures) of the operator called ``name`` over every context."""
        return self.experience.counts(name)

    def nominal_cost(self, name: str) -> float:
        """The cost of an operator before experience: K's own for a domain action; for a
        learned operator, that of the action it was learned to replace (else that of K's
        action with the same controller)."""
        key = name.lower()
        if key not in self._nominal:
            self._nominal[key] = self._nominal_cost(key)
        return self._nominal[key]

    def _nominal_cost(self, key: str) -> float:
        domain = {op.name.lower(): op.cost for op in self.actions}
        seen: set[str] = set()
        while key not in domain and key not in seen:  # follow what each learned operator replaced
            seen.add(key)
            learned = self.learned_operator(key)
            targets = [t.lower() for t in (learned.replaces, learned.action) if t is not None]
            key = next((t for t in targets if t in self._variables and t not in seen), key)
        return domain.get(key, 1.0)

    def cost(self, name: str) -> float:
        """The plan cost of an operator by its experience in every context."""
        return self.experience.cost(name, self.nominal_cost(name))

    def context(self, step: GroundAction, state: State) -> Context:
        """What holds of ``step``'s arguments in ``state``, lifted to its operator's variables."""
        variables = self._variables.get(step.name.lower())
        if variables is None:
            raise UnknownNameError("operator", step.name, [op.name for op in self.operators()])
        return step_context(variables, step.args, state, self.constants)

    def allowed(self, step: GroundAction, state: State, *, predicted: bool = False) -> bool:
        """Whether experience allows ``step`` in ``state``: not where its operator has failed
        in the same context and never worked there (the planner then looks elsewhere).

        In a ``predicted`` state (one a plan expects to reach, not one perceived), a context
        never seen is judged by the seen contexts it contains: a step that failed where
        F held, and never worked where only facts of the predicted context held, stays out
        wherever F still holds. Otherwise an untried step that merely adds a fact to the
        context (``touching``) would let the planner try a_f again, where the learned
        operator that made it work is known. A perceived state is judged by its own
        context: after a trial changed it, the re-plan gets a fair chance.
        """
        if not self.experience.entries:
            return True
        context = self.context(step, state)
        successes, failures = self.experience.counts(step.name, context)
        if predicted and not successes and not failures:
            successes, failures = self.experience.counts_within(step.name, context)
        return successes > 0 or failures == 0

    def step_cost(self, step: GroundAction, state: State) -> float:
        """The plan cost of ``step`` taken in ``state``: by its operator's experience in that
        context where it ran there before, else in every context."""
        return self.experience.cost(step.name, self.nominal_cost(step.name), self.context(step, state))

    def operators(self) -> list[Operator]:
        """Every operator the planner may use, at its cost by experience: the domain's
        actions, then the learned ones."""
        ops = [replace(op, cost=self.cost(op.name)) for op in self.actions]
        return ops + [op.as_operator(self.cost(op.name), self.is_subtype) for op in self.learned]

    def operator(self, name: str) -> Operator:
        """The operator called ``name``.

        Raises:
            UnknownNameError: no such operator.
        """
        for op in self.operators():
            if op.name.lower() == name.lower():
                return op
        raise UnknownNameError("operator", name, [op.name for op in self.operators()])

    def is_learned(self, name: str) -> bool:
        """Whether ``name`` is one of the learned operators (K' beyond K's actions)."""
        return any(op.name.lower() == name.lower() for op in self.learned)

    def learned_operator(self, name: str) -> LearnedOperator:
        """The learned operator called ``name`` (for its controller settings)."""
        for op in self.learned:
            if op.name.lower() == name.lower():
                return op
        raise UnknownNameError("learned operator", name, [op.name for op in self.learned])

    def claims(self, call: TrialSpec, atom: Fluent, *, add: bool, objects: Mapping[str, str]) -> bool:
        """Whether some operator of K, executed by this controller call, has the effect of
        making ``atom`` true (``add``) or false.

        Only effects count, not preconditions: after a novelty the preconditions are what
        may no longer mean what K thinks. The call's arguments bind the operator's
        controller arguments; its other parameters bind to any object of their type
        (``push(?o)`` aimed at ``?c`` claims ``(in ?o ?c)`` for every container). A
        naive action claims its effects for every controller setting; a learned operator
        only for its own settings. A symmetric atom (``touching``) is read both ways.

        Args:
            objects: object name -> type, for the objects the atom and the call name
                (constants are known to K).
        """
        types = {**self.constants, **objects}
        readings = [atom, (atom[0], *reversed(atom[1:]))] if atom[0] in SYMMETRIC_PREDICATES else [atom]
        for op in (*self.actions, *(learned.as_operator(0.0, self.is_subtype) for learned in self.learned)):
            controller = op.controller
            if controller.action != call.action or controller.params not in (None, call.params):
                continue
            parameter_types = dict(op.parameters)
            binding = dict(zip(controller.arguments, call.arguments))
            if not all(self.is_subtype(types.get(obj, ""), parameter_types[var]) for var, obj in binding.items()):
                continue
            effects = op.add if add else op.delete
            if any(_unifies(e, a, binding, parameter_types, types, self.is_subtype) for e in effects for a in readings):
                return True
        return False

    def is_subtype(self, kind: str, ancestor: str) -> bool:
        """Whether an object of type ``kind`` may fill a parameter of type ``ancestor``."""
        seen: set[str] = set()
        current: str | None = kind
        while current is not None and current not in seen:
            if current == ancestor:
                return True
            seen.add(current)
            current = self._types.get(current)
        return ancestor == "object"

    def known_types(self) -> set[str]:
        """Every declared type, its ancestors and ``object``."""
        return {*self._types, *(p for p in self._types.values() if p is not None), "object"}

    # ------------------------------------------------------------------ PDDL

    def to_domain(self, *, actions: Sequence[Action] | None = None, requirements: Iterable[str] = REQUIREMENTS) -> Domain:
        """K as a `pddl` library domain (type-checked by the library).

        Args:
            actions: the actions as written (default: every operator at its cost by
                experience in every context); the PDDL export writes its own.
            requirements: the requirements to declare; without ``action-costs`` the
                domain declares no ``total-cost`` function.
        """
        requirements = tuple(requirements)
        constants = self.constants
        predicates = [
            Predicate(name, *(Variable(v[1:], [t]) for v, t in params)) for name, params in self.predicate_signatures
        ]
        try:
            return Domain(
                self.name,
                requirements={Requirements(r) for r in requirements},
                types=dict(self.type_parents),
                constants=[Constant(c, t) for c, t in self.constant_types],
                predicates=predicates,
                functions={NumericFunction(TOTAL_COST): "number"} if "action-costs" in requirements else None,
                actions=[operator_to_pddl(op, constants) for op in self.operators()] if actions is None else list(actions),
            )
        except (PDDLValidationError, ValueError, AssertionError) as exc:
            raise LlcpsError(f"the knowledge base is not a valid PDDL domain: {exc}") from exc

    def to_pddl(self) -> str:
        """K as PDDL domain text, learned operators included."""
        return str(self.to_domain()) + "\n"


@functools.cache
def _default_kb() -> KnowledgeBase:
    return KnowledgeBase.from_pddl(default_domain_pddl())


def clear_caches() -> None:
    _default_kb.cache_clear()


def _unifies(
    effect: Fluent,
    atom: Fluent,
    binding: Mapping[str, str],
    parameter_types: Mapping[str, str],
    types: Mapping[str, str],
    is_subtype: Callable[[str, str], bool],
) -> bool:
    """Whether a lifted effect, under ``binding`` and free bindings of its other variables
    to objects of their type, is ``atom``."""
    if effect[0] != atom[0] or len(effect) != len(atom):
        return False
    bound = dict(binding)
    for term, obj in zip(effect[1:], atom[1:]):
        if not is_variable(term):
            if term != obj:
                return False
        elif term in bound:
            if bound[term] != obj:
                return False
        elif obj in types and is_subtype(types[obj], parameter_types[term]):
            bound[term] = obj
        else:
            return False
    return True
