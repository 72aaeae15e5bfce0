"""Knowledge-base expansion K -> K': operators learned from exploration trials.

A trial that resolves a novelty (an action controller with fixed settings, run on some
entities) becomes a :class:`LearnedOperator`: its effects are what the trial was observed
to change, and its preconditions the *context* it was observed in (see
:func:`learn_operator`), so that it is chosen only where its effect on its arguments was
seen. The planner uses it like any action of K at a cost set by experience
(:mod:`llcps.symbolic.knowledge_base`), and the executor maps it back to the controller
settings that produced it.

Where a_f itself failed is remembered by experience (:mod:`llcps.symbolic.experience`):
a step is not planned again in a context where its operator has failed and never
worked, so the planner reaches for what was learned there instead.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import fields, dataclass, replace
from typing import Callable, Collection, Mapping, Sequence

from llcps.domain import ACTION_ARITY, ACTIONS, ORIENTATIONS, ControllerParams, Fluent, State, fluent
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError
from llcps.symbolic.pddl_domain import default_constants, default_is_subtype, default_predicates
from llcps.symbolic.lifted import (
    EQUALITY,
    Controller,
    Operator,
    operator_to_pddl,
    sort_fluents,
    substitute,
)

#: Predicates left out of a learned operator's context: the hand holds nothing between trials.
CONTEXT_IGNORED: frozenset[str] = frozenset({"holding"})

#: Variable stems for parameter types; other types use their first letter.
_TYPE_STEMS = {"item": "o", "container": "c", "surface": "s", "entity": "e"}

_NAME = re.compile(
    rf"(?P<action>{'|'.join(sorted(ACTIONS, key=len, reverse=True))})"
    rf"_(?P<orientation>{'|'.join(ORIENTATIONS)})"
    r"_r(?P<rate>[0-9a-z+-]+)_m(?P<magnitude>[0-9a-z+-]+)(?:_(?P<copy>[0-9]+))?"
)


def _encode_number(value: float) -> str:
    text = repr(float(value))
    if text.endswith(".0"):
        text = text[:-2]
    return text.replace(".", "p")


def _decode_number(text: str) -> float:
    return float(text.replace("p", "."))


def operator_name(action: str, params: ControllerParams, copy: int | None = None) -> str:
    """The PDDL name of a learned operator, which encodes its controller settings.

    ``push`` at 0.2 m/s over 0.3 m from the front is ``push_front_r0p2_m0p3`` (``p`` is
    the decimal point, which PDDL names cannot contain); a second, different operator
    with the same settings gets ``_2``.
    """
    name = f"{action}_{params.orientation}_r{_encode_number(params.rate)}_m{_encode_number(params.movement_magnitude)}"
    return name if copy is None or copy <= 1 else f"{name}_{copy}"


def parse_operator_name(name: str) -> tuple[str, ControllerParams, int] | None:
    """Recover (action, controller settings, copy number) from a learned operator's name.

    Returns:
        None when ``name`` is not the name of a learned operator.
    """
    match = _NAME.fullmatch(name.lower())
    if match is None:
        return None
    try:
        params = ControllerParams(
            rate=_decode_number(match["rate"]),
            movement_magnitude=_decode_number(match["magnitude"]),
            orientation=match["orientation"],
        )
    except ValueError:
        return None
    return match["action"], params, int(match["copy"] or 1)


@dataclass(frozen=True)
class LearnedOperator:
    """An operator of K' learned from one exploration trial.

    Attributes:
        name: a PDDL name encoding the controller settings (see :func:`operator_name`).
        action: the controller that executes it.
        arguments: the parameter variables that are the controller's physical arguments.
        params: the controller settings the trial used.
        parameters: ``(variable, type)`` pairs; the controller's arguments come first.
        preconditions: lifted fluents that held among the parameters before the trial.
        add: lifted fluents the trial was observed to make true.
        delete: lifted fluents the trial was observed to make false.
        negative_preconditions: lifted fluents over the parameters that did not hold.
        replaces: the operator whose failure it was learned to get around (a_f), whose
            nominal cost it takes; None when unknown (read back from PDDL).
        source_arguments: the objects the parameters were lifted from, in parameter order
            (None when read back from PDDL, which does not record them).
    """

    name: str
    action: str
    arguments: tuple[str, ...]
    params: ControllerParams
    parameters: tuple[tuple[str, str], ...]
    preconditions: frozenset[Fluent]
    add: frozenset[Fluent]
    delete: frozenset[Fluent]
    negative_preconditions: frozenset[Fluent] = frozenset()
    replaces: str | None = None
    source_arguments: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if any(a[0] == EQUALITY for a in self.preconditions | self.negative_preconditions):
            raise ValueError(f"{self.name}: equality tests are derived from the parameters, not stored")
        self.as_operator(1.0)  # validates names, variables and the controller binding
        if self.source_arguments is not None and len(self.source_arguments) != len(self.parameters):
            raise ValueError(f"{self.name}: source_arguments {self.source_arguments} do not match parameters {self.parameters}")

    @property
    def variables(self) -> tuple[str, ...]:
        return tuple(v for v, _ in self.parameters)

    def distinct(self, is_subtype: Callable[[str, str], bool] | None = None) -> frozenset[Fluent]:
        """``(= ?a ?b)`` tests the operator must fail: one per pair of parameters that one
        object could fill (their types are compatible) but that were distinct entities
        where the operator was learned.

        A trial on (block bin can) says nothing of (can bin can): without these tests the
        planner could bind one entity to two parameters. Pairs bound to one entity when
        the operator was learned (``source_arguments``) are left free.

        Args:
            is_subtype: the knowledge base's type order (default: the naive domain's).
        """
        is_subtype = is_subtype or default_is_subtype
        sources = self.source_arguments
        tests = set()
        for (i, (a, ta)), (j, (b, tb)) in itertools.combinations(enumerate(self.parameters), 2):
            if sources is not None and sources[i] == sources[j]:
                continue
            if is_subtype(ta, tb) or is_subtype(tb, ta):
                tests.add((EQUALITY, a, b))
        return frozenset(tests)

    def as_operator(self, cost: float, is_subtype: Callable[[str, str], bool] | None = None) -> Operator:
        """The operator the planner searches with, at ``cost`` (set by the knowledge base),
        with the inequalities of :meth:`distinct` among its negative preconditions."""
        return Operator(
            name=self.name,
            parameters=self.parameters,
            preconditions=self.preconditions,
            negative_preconditions=self.negative_preconditions | self.distinct(is_subtype),
            add=self.add,
            delete=self.delete,
            cost=cost,
            controller=Controller(action=self.action, arguments=self.arguments, params=self.params),
        )

    @classmethod
    def from_operator(cls, op: Operator) -> LearnedOperator:
        """Recognise a learned operator (read back from PDDL) by its name; see :meth:`from_fields`."""
        return cls.from_fields(
            name=op.name,
            parameters=op.parameters,
            preconditions=op.preconditions,
            negative_preconditions=op.negative_preconditions,
            add=op.add,
            delete=op.delete,
        )

    @classmethod
    def from_fields(
        cls,
        *,
        name: str,
        parameters: tuple[tuple[str, str], ...],
        preconditions: frozenset[Fluent],
        negative_preconditions: frozenset[Fluent],
        add: frozenset[Fluent],
        delete: frozenset[Fluent],
        cost: float = 0.0,
    ) -> LearnedOperator:
        """A learned operator from an action's parts; the controller comes from the name.

        The controller's physical arguments are the first parameters, as many as the
        controller takes. ``cost`` is accepted for PDDL round trips and ignored: a learned
        operator's cost comes from the knowledge base's experience. Inequalities between
        parameters (``(not (= ?a ?b))``) are dropped: :meth:`distinct` derives them again.

        Raises:
            LlcpsError: the name does not encode controller settings, there are too few
                parameters, or a precondition is another equality test.
        """
        parsed = parse_operator_name(name)
        if parsed is None:
            raise LlcpsError(
                f"action {name} is neither one of {ACTIONS} nor a learned operator",
                hint="learned operators are named like push_front_r0p2_m0p3",
            )
        variables = {v for v, _ in parameters}
        inequalities = {a for a in negative_preconditions if a[0] == EQUALITY and set(a[1:]) <= variables}
        negative_preconditions = frozenset(negative_preconditions - inequalities)
        if any(a[0] == EQUALITY for a in preconditions | negative_preconditions):
            raise LlcpsError(
                f"learned operator {name} has an equality test", hint="learned operators test fluents and parameter inequalities only"
            )
        action, params, _ = parsed
        arity = ACTION_ARITY[action]
        if len(parameters) < arity:
            raise LlcpsError(f"learned operator {name} has fewer parameters than the {action} controller takes ({arity})")
        return cls(
            name=name,
            action=action,
            arguments=tuple(v for v, _ in parameters[:arity]),
            params=params,
            parameters=parameters,
            preconditions=preconditions,
            add=add,
            delete=delete,
            negative_preconditions=negative_preconditions,
        )

    def renamed(self, name: str) -> LearnedOperator:
        return replace(self, name=name)

    def same_knowledge(self, other: LearnedOperator) -> bool:
        """Equal up to its name and where it was learned: adding it again teaches nothing."""
        return self.same_skill(other) and self.context == other.context

    def same_skill(self, other: LearnedOperator) -> bool:
        """The same controller settings with the same effects, whatever the context."""
        ignored = {"name", "source_arguments", "preconditions", "negative_preconditions", "replaces"}
        return all(
            getattr(self, f.name) == getattr(other, f.name) for f in fields(self) if f.name not in ignored
        )

    @property
    def context(self) -> tuple[frozenset[Fluent], frozenset[Fluent]]:
        """(positive, negative) preconditions: where the operator was seen to work."""
        return self.preconditions, self.negative_preconditions

    def generalized(self, other: LearnedOperator) -> LearnedOperator:
        """This operator applicable wherever either was seen to work: the contexts' intersection.

        Raises:
            ValueError: ``other`` is not the same skill.
        """
        if not self.same_skill(other):
            raise ValueError(f"{other.name} is not the same skill as {self.name}")
        return replace(
            self,
            preconditions=self.preconditions & other.preconditions,
            negative_preconditions=self.negative_preconditions & other.negative_preconditions,
        )

    def to_pddl(
        self, constant_types: Mapping[str, str] | None = None, *, cost: float = 1.0, is_subtype: Callable[[str, str], bool] | None = None
    ) -> str:
        """The operator as a PDDL ``:action`` (rendered by the `pddl` library)."""
        return str(operator_to_pddl(self.as_operator(cost, is_subtype), constant_types))

    def controller_spec(self, binding: Mapping[str, str] | Sequence[str]) -> TrialSpec:
        """The trial that executes this operator on concrete objects.

        Args:
            binding: variable -> object, or the objects in parameter order (a plan step's args).
        """
        if not isinstance(binding, Mapping):
            if len(binding) != len(self.parameters):
                raise ValueError(f"{self.name} takes {len(self.parameters)} argument(s), got {tuple(binding)}")
            binding = dict(zip(self.variables, binding))
        return TrialSpec(action=self.action, arguments=tuple(binding[v] for v in self.arguments), params=self.params)

    def to_json(self) -> dict[str, object]:
        """A JSON-safe dict for the experience store."""
        return {
            "name": self.name,
            "action": self.action,
            "arguments": list(self.arguments),
            "params": {
                "rate": self.params.rate,
                "movement_magnitude": self.params.movement_magnitude,
                "orientation": self.params.orientation,
            },
            "parameters": [list(p) for p in self.parameters],
            "preconditions": [list(a) for a in sort_fluents(self.preconditions)],
            "negative_preconditions": [list(a) for a in sort_fluents(self.negative_preconditions)],
            "add": [list(a) for a in sort_fluents(self.add)],
            "delete": [list(a) for a in sort_fluents(self.delete)],
            "replaces": self.replaces,
            "source_arguments": list(self.source_arguments) if self.source_arguments is not None else None,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, object]) -> LearnedOperator:
        """Rebuild an operator stored with :meth:`to_json`.

        Raises:
            LlcpsError: the record is malformed.
        """
        try:
            params = data["params"]
            source = data.get("source_arguments")
            return cls(
                name=str(data["name"]),
                action=str(data["action"]),
                arguments=tuple(data["arguments"]),  # type: ignore[arg-type]
                params=ControllerParams(
                    rate=float(params["rate"]),  # type: ignore[index]
                    movement_magnitude=float(params["movement_magnitude"]),  # type: ignore[index]
                    orientation=str(params["orientation"]),  # type: ignore[index]
                ),
                parameters=tuple((str(v), str(t)) for v, t in data["parameters"]),  # type: ignore[union-attr]
                preconditions=frozenset(fluent(*a) for a in data["preconditions"]),  # type: ignore[union-attr]
                add=frozenset(fluent(*a) for a in data["add"]),  # type: ignore[union-attr]
                delete=frozenset(fluent(*a) for a in data["delete"]),  # type: ignore[union-attr]
                negative_preconditions=frozenset(fluent(*a) for a in data.get("negative_preconditions", ())),  # type: ignore[union-attr]
                replaces=None if data.get("replaces") is None else str(data["replaces"]),
                source_arguments=tuple(source) if source is not None else None,  # type: ignore[arg-type]
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise LlcpsError(f"malformed learned operator record: {exc}", hint="the record must come from LearnedOperator.to_json()") from exc


def _relevant_entities(arguments: Collection[str], before: State, after: State, constants: Collection[str]) -> set[str]:
    """The trial's arguments and every entity one relation away from them (e.g. ``(in cube tray)``)."""
    base = set(arguments)
    linked = set(base)
    for atom in before | after:
        if len(atom) > 2 and base.intersection(atom[1:]):
            linked.update(atom[1:])
    return linked - set(constants)


def learn_operator(
    *,
    spec: TrialSpec,
    before: State,
    after: State,
    objects: Mapping[str, str],
    focus: Collection[str] = (),
    replaces: str | None = None,
    constants: Collection[str] | None = None,
    predicates: Mapping[str, int] | None = None,
) -> LearnedOperator:
    """Turn one executed trial into an operator of K'.

    Parameters are the trial's arguments plus every entity of an observed change that
    matters: one that is an argument, in ``focus``, or related to one of them by a fluent
    before or after the trial (pushing the tray matters to the cube in it). Constants
    of the domain (``table``) stay constants. Effects are the observed differences that
    mention only parameters and constants.

    Preconditions are the *context* the trial was observed in, and nothing else: every
    fact over the parameters (and constants) as it was before the trial, both the ones
    that held (positive preconditions) and, under the closed-world assumption, the ones
    that did not (negative preconditions) — for each predicate of K but ``holding``,
    over distinct terms. Facts about other entities are left out: they do not matter to
    what the controller does to its arguments. So the operator is chosen only where its
    arguments stand as they stood when its effect was seen; a push learned for a can and
    an unreachable bin says nothing about a bin within reach, nor about a cup holding a
    ball. Where the same skill resolves a novelty again in another context, the knowledge
    base keeps what the two contexts share (:meth:`LearnedOperator.generalized`).

    Args:
        spec: the trial (controller, arguments, settings).
        before: the perceived state before the trial.
        after: the perceived state after it.
        objects: object -> type for every entity that can become a parameter.
        focus: extra entities that matter, e.g. the failed action's arguments.
        replaces: the failed action a_f the trial gets around (see :class:`LearnedOperator`).
        constants: names that stay constants; defaults to the default domain's constants.
        predicates: predicate -> arity of the knowledge base the context is written in;
            defaults to the default domain's predicates.
    """
    if constants is None or predicates is None:
        constants = default_constants().keys() if constants is None else constants
        predicates = default_predicates() if predicates is None else predicates
    constants = set(constants)
    before, after = frozenset(before), frozenset(after)
    changed = (after - before) | (before - after)
    relevant = _relevant_entities((*spec.arguments, *focus), before, after, constants)
    extra = sorted({e for atom in changed for e in atom[1:] if e in relevant} - set(spec.arguments))
    entities = list(dict.fromkeys((*spec.arguments, *extra)))

    binding: dict[str, str] = {}
    parameters: list[tuple[str, str]] = []
    used: set[str] = set()
    for entity in entities:
        if entity in constants:
            raise ValueError(f"the trial argument {entity!r} is a domain constant, not an object")
        if entity not in objects:
            raise ValueError(f"entity {entity!r} has no type in objects")
        kind = objects[entity]
        stem = _TYPE_STEMS.get(kind, kind[:1].lower() or "x")
        var, n = f"?{stem}", 1
        while var in used:
            n += 1
            var = f"?{stem}{n}"
        used.add(var)
        binding[entity] = var
        parameters.append((var, kind))

    def lift(atoms: frozenset[Fluent]) -> frozenset[Fluent]:
        keep = {a for a in atoms if all(t in binding or t in constants for t in a[1:])}
        return frozenset(substitute(a, binding) for a in keep)

    holds = lift(before)
    possible = _context_atoms(entities, sorted(constants), predicates)
    return LearnedOperator(
        name=operator_name(spec.action, spec.params),
        action=spec.action,
        arguments=tuple(binding[a] for a in spec.arguments),
        params=spec.params,
        parameters=tuple(parameters),
        preconditions=frozenset(a for a in holds if a[0] not in CONTEXT_IGNORED),
        add=lift(after - before),
        delete=lift(before - after),
        negative_preconditions=frozenset(substitute(a, binding) for a in possible if a not in before),
        replaces=replaces,
        source_arguments=tuple(entities),
    )


def _context_atoms(entities: Sequence[str], constants: Sequence[str], predicates: Mapping[str, int]) -> set[Fluent]:
    """Every ground fact over distinct ``entities`` (a constant allowed in any position but
    the first) that a context records: the predicates of K but :data:`CONTEXT_IGNORED`."""
    atoms: set[Fluent] = set()
    for predicate, arity in sorted(predicates.items()):
        if predicate in CONTEXT_IGNORED or arity < 1:
            continue
        pools = [list(entities)] + [list(entities) + list(constants)] * (arity - 1)
        for terms in itertools.product(*pools):
            if len(set(terms)) == len(terms) and any(t in entities for t in terms):
                atoms.add(fluent(predicate, *terms))
    return atoms
