"""Experience with operators: how often each one, executed as a plan step, achieved the
effects the plan relied on — overall and in each *context* it was executed in.

A context is what held of the step's arguments just before it ran: the facts over its
arguments (and the domain's constants), lifted to the operator's variables, e.g.
``{(visible ?o), (near ?o ?c), (on ?o table)}`` for ``push ?o ?c``. Counting per context
lets the robot remember that a step failed *here* without forgetting that it works
elsewhere: a push that drops the cube into the bucket every day but was stopped once by
a fence is dear where the fence stands and cheap where it does not.

The plan cost of a step (:meth:`Experience.cost`) is :func:`experience_cost` of its
operator's nominal cost, from its counts in the step's context when it has been executed
there, else from its counts in every context.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Collection, Iterable, Iterator, Mapping, Sequence

from llcps.domain import Fluent, State
from llcps.symbolic.lifted import substitute

Context = frozenset[Fluent]
"""Lifted facts over a step's arguments before it ran (variables of its operator)."""


def experience_cost(nominal: float, successes: int, failures: int) -> float:
    """An operator's plan cost after ``successes`` and ``failures`` as a plan step.

    The nominal cost divided by the Laplace-smoothed success rate (s + 1) / (s + f + 2),
    relative to the rate 1/2 of an operator never executed:
    ``nominal * (s + f + 2) / (2 * (s + 1))``. Never executed: the nominal cost; one
    success: 0.75 of it; one failure: 1.5 times; many successes: toward half of it;
    many failures: without bound.
    """
    if successes < 0 or failures < 0:
        raise ValueError(f"execution counts must be >= 0, got {successes} and {failures}")
    return nominal * (successes + failures + 2) / (2 * (successes + 1))


def step_context(variables: Sequence[str], args: Sequence[str], state: State, constants: Collection[str]) -> Context:
    """The context of a ground step: the facts of ``state`` over its arguments and the
    constants (at least one argument each), lifted to the operator's ``variables``."""
    binding: dict[str, str] = {}
    for var, obj in zip(variables, args):
        binding.setdefault(obj, var)
    allowed = set(binding) | set(constants)
    return frozenset(
        substitute(atom, binding)
        for atom in state
        if all(t in allowed for t in atom[1:]) and any(t in binding for t in atom[1:])
    )


@dataclass(frozen=True)
class Experience:
    """(successes, failures) per operator and context; a value (adding returns a new one).

    Attributes:
        entries: ``(operator, context, successes, failures)``, one per operator and context,
            sorted; operator names compare case-insensitively, as in PDDL.
    """

    entries: tuple[tuple[str, tuple[Fluent, ...], int, int], ...] = ()

    @classmethod
    def of(cls, executions: Iterable[tuple[str, Iterable[Fluent], bool]]) -> Experience:
        """Experience from ``(operator, context, success)`` executions, in any order."""
        counts: dict[tuple[str, tuple[Fluent, ...]], list[int]] = {}
        for name, context, success in executions:
            key = (str(name).lower(), tuple(sorted(context)))
            counts.setdefault(key, [0, 0])[0 if success else 1] += 1
        return cls(tuple(sorted((name, ctx, s, f) for (name, ctx), (s, f) in counts.items())))

    @classmethod
    def from_counts(cls, counts: Iterable[tuple[str, Iterable[Sequence[str]], int, int]]) -> Experience:
        """Experience from ``(operator, context atoms, successes, failures)`` rows (the store's)."""
        merged: dict[tuple[str, tuple[Fluent, ...]], list[int]] = {}
        for name, context, s, f in counts:
            key = (str(name).lower(), tuple(sorted(tuple(atom) for atom in context)))
            entry = merged.setdefault(key, [0, 0])
            entry[0] += int(s)
            entry[1] += int(f)
        return cls(tuple(sorted((name, ctx, s, f) for (name, ctx), (s, f) in merged.items())))

    def __iter__(self) -> Iterator[tuple[str, Context, bool]]:
        """Every execution as ``(operator, context, success)`` (for :meth:`of`)."""
        for name, ctx, s, f in self.entries:
            context = frozenset(ctx)
            for _ in range(s):
                yield name, context, True
            for _ in range(f):
                yield name, context, False

    def added(self, name: str, context: Context, success: bool) -> Experience:
        """This experience and one more execution."""
        return Experience.of([*self, (name, context, success)])

    def counts(self, name: str, context: Context | None = None) -> tuple[int, int]:
        """(successes, failures) of ``name`` in ``context``, or in every context (None)."""
        key = name.lower()
        want = None if context is None else tuple(sorted(context))
        s = f = 0
        for entry, ctx, es, ef in self.entries:
            if entry == key and (want is None or ctx == want):
                s, f = s + es, f + ef
        return s, f

    def counts_within(self, name: str, context: Context) -> tuple[int, int]:
        """(successes, failures) of ``name`` in every context ``context`` contains: where
        everything that held then holds now (and maybe more)."""
        key = name.lower()
        s = f = 0
        for entry, ctx, es, ef in self.entries:
            if entry == key and context.issuperset(ctx):
                s, f = s + es, f + ef
        return s, f

    def cost(self, name: str, nominal: float, context: Context | None = None) -> float:
        """The plan cost of ``name``: from its counts in ``context`` where it was executed
        there, else from its counts in every context (see the module docstring)."""
        if context is not None:
            s, f = self.counts(name, context)
            if s or f:
                return experience_cost(nominal, s, f)
        return experience_cost(nominal, *self.counts(name))

    def totals(self) -> Mapping[str, tuple[int, int]]:
        """(successes, failures) of every operator over all its contexts."""
        out: dict[str, tuple[int, int]] = {}
        for name, _, s, f in self.entries:
            a, b = out.get(name, (0, 0))
            out[name] = (a + s, b + f)
        return out
