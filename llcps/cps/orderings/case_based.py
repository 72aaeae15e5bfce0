"""``case-based``: try what resolved the most similar past failures first, then the default.

The control every lifelong claim needs: if the world model cannot beat a lookup of
past solutions, that must show. A *case* is a past episode on the branch (or on a
branch it descends from, up to its fork point) that ended with a resolving trial. Its
failure is what the episode recorded: the failed step a_f and the atoms it left
missing. Each case is compared with the present failure by

- the missing atoms *in roles*: every argument replaced by its role, the first or
  second argument of a_f or another entity, so ``(in cube bucket)`` missing after
  ``push(cube, bucket)`` is the same case whatever the entities are called (Jaccard
  similarity of the two sets of signed role atoms);
- the failed action: :data:`SAME_ACTION` more when a_f's operator is the same;
- the scene geometry: the case's resolving trial is mapped to the present candidates of
  its action and settings, an argument in a role of a_f to the entity in that role, any
  other to the entity most like it (Table-1 volume and position relative to the robot);
  :data:`GEOMETRY` times that match (1 for the same place and size) is added.

Cases are tried best first (ties: the newest episode first), each as the one candidate
its resolving trial maps to; then the default ordering (``ORDERINGS.default``) takes
over, told about every trial taken so far. What the store holds about a past episode
is read as untrusted text: a summary that does not parse is no case.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Iterable, Sequence

from llcps.cps.orderings.base import Exploration, Ordering

if TYPE_CHECKING:
    from llcps.domain import EntityFeatures, State
    from llcps.store import Store
    from llcps.trial_records import TrialRecord

#: Weight of the same failed operator in a case's similarity (missing atoms weigh at most 1).
SAME_ACTION = 0.5
#: Weight of the geometric match of the mapped candidate's arguments.
GEOMETRY = 0.5
#: Most past episodes looked at (the newest).
MAX_CASES = 500
#: Longest stored text parsed as a failure.
_MAX_TEXT = 4000
_ATOM = re.compile(r"\(([^()]{1,200})\)")

SignedAtom = tuple[tuple[str, ...], bool]


def role_atoms(atoms: Iterable[SignedAtom], failed_args: Sequence[str]) -> frozenset[SignedAtom]:
    """The atoms with each argument replaced by its role: ``a0``/``a1`` for a_f's
    arguments, ``o`` for any other entity."""
    roles = {name: f"a{i}" for i, name in enumerate(failed_args)}
    return frozenset(((atom[0], *(roles.get(t, "o") for t in atom[1:])), sign) for atom, sign in atoms)


def parse_failure(failed_action: object, missing_effects: object) -> tuple[str, tuple[str, ...], list[SignedAtom]] | None:
    """(operator, arguments, signed missing atoms) from an episode's stored summary
    (``(push cube bucket)``, ``(push cube bucket) failed: missing (in cube bucket); still (x y)``);
    None when they do not parse."""
    if not isinstance(failed_action, str) or not isinstance(missing_effects, str):
        return None
    if len(failed_action) > _MAX_TEXT or len(missing_effects) > _MAX_TEXT or "failed:" not in missing_effects:
        return None
    step = failed_action.strip().strip("()").split()
    if not step:
        return None
    atoms: list[SignedAtom] = []
    for part in missing_effects.split("failed:", 1)[1].split(";"):
        part = part.strip()
        sign = True if part.startswith("missing") else False if part.startswith("still") else None
        if sign is None:
            return None
        atoms.extend((tuple(m.split()), sign) for m in _ATOM.findall(part) if m.split())
    return step[0], tuple(step[1:]), atoms


def geometry_match(a: EntityFeatures, b: EntityFeatures) -> float:
    """1 for two entities of the same size at the same place (relative to the robot), less the further apart."""
    position = math.dist(
        (a.vector_magnitude * a.unit_x, a.vector_magnitude * a.unit_y, a.vector_magnitude * a.unit_z),
        (b.vector_magnitude * b.unit_x, b.vector_magnitude * b.unit_y, b.vector_magnitude * b.unit_z),
    )
    size = abs(math.log(max(a.volume, 1e-9) / max(b.volume, 1e-9)))
    return math.exp(-(position / 0.1 + size))


@dataclass(frozen=True)
class Case:
    """A past failure and the trial that resolved it."""

    episode_id: int
    operator: str
    failed_args: tuple[str, ...]
    missing: frozenset[SignedAtom]
    trial: TrialRecord


def past_cases(store: Store, branch: str, *, exclude: int | None = None) -> list[Case]:
    """The resolved episodes ``branch`` sees, newest first (at most :data:`MAX_CASES`)."""
    chain: list[tuple[str, float]] = []
    name: str | None = branch
    limit = math.inf
    while name is not None:
        info = store.resolve_branch(name)
        chain.append((info.name, limit))
        if info.parent is not None:
            limit = min(limit, info.fork_point)
        name = info.parent
    cases: list[Case] = []
    for branch_name, upto in chain:
        for episode in store.list_episodes(branch=branch_name, limit=MAX_CASES):
            summary = episode.summary if isinstance(episode.summary, dict) else {}
            resolving = summary.get("resolving_trial_id")
            if episode.id == exclude or episode.status != "solved" or not isinstance(resolving, int) or resolving > upto:
                continue
            parsed = parse_failure(summary.get("failed_action"), summary.get("missing_effects"))
            if parsed is None:
                continue
            operator, args, atoms = parsed
            try:
                trial = store.get_trial(resolving)
            except Exception:  # noqa: BLE001 - a row that does not load is no case
                continue
            cases.append(Case(episode.id, operator, args, role_atoms(atoms, args), trial))
    cases.sort(key=lambda c: -c.episode_id)
    return cases[:MAX_CASES]


class CaseBased(Ordering):
    """Past resolving trials of similar failures first, then the default ordering.

    Attributes:
        reused: the candidate indices taken from cases, in the order they are tried.
        similarity: each reused candidate's case score.
    """

    name: ClassVar[str] = "case-based"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        store, branch = exploration.store, exploration.branch
        cases = past_cases(store, branch, exclude=exploration.episode_id) if store is not None and branch is not None else []
        scored: dict[int, tuple[float, int]] = {}
        for case in cases:
            found = self._match(case)
            if found is not None:
                index, score = found
                if index not in scored or (score, case.episode_id) > scored[index]:
                    scored[index] = (score, case.episode_id)
        ranked = sorted(scored.items(), key=lambda item: (-item[1][0], -item[1][1], item[0]))
        self.reused = [index for index, _ in ranked]
        self.similarity = [score for _, (score, _) in ranked]
        self.fallback: Ordering | None = None
        self._tried: list[int] = []

    def _match(self, case: Case) -> tuple[int, float] | None:
        """The present candidate ``case``'s resolving trial maps to, and the case's score."""
        point = self.exploration.point
        failure = point.failure
        failed_args = failure.step.args
        here = role_atoms([(a, True) for a in failure.missing_add] + [(a, False) for a in failure.missing_del], failed_args)
        union = here | case.missing
        similarity = len(here & case.missing) / len(union) if union else 0.0
        similarity += SAME_ACTION * (case.operator == failure.step.name)
        if similarity <= 0.0:
            return None
        past = case.trial
        roles = {name: i for i, name in enumerate(case.failed_args)}
        past_features = past.features
        best: tuple[float, int] | None = None
        for i, candidate in enumerate(point.candidates):
            spec = candidate
            if spec.action != past.spec.action or spec.params != past.spec.params or len(spec.arguments) != len(past.spec.arguments):
                continue
            match = 0.0
            for slot, (now, then) in enumerate(zip(spec.arguments, past.spec.arguments)):
                role = roles.get(then)
                if role is not None and role < len(failed_args):
                    match += 1.0 if failed_args[role] == now else 0.0
                else:
                    match += geometry_match(point.inputs[i].features[slot], past_features[slot])
            match /= max(len(spec.arguments), 1)
            if best is None or match > best[0]:
                best = (match, i)
        if best is None:
            return None
        return best[1], similarity + GEOMETRY * best[0]

    def choose(self) -> int:
        for index in self.reused:
            if index in self.remaining:
                return index
        if self.fallback is None:
            # The cases are spent: the default ordering takes over, from the model taken
            # up to the trials so far, without the candidates tried.
            from llcps.cps.orderings import ORDERINGS, get_ordering

            if self._tried:
                self.exploration.update(self._tried)
            self.fallback = get_ordering(ORDERINGS.default)(self.exploration)
            # What this ordering no longer has: the candidates tried, and those excluded
            # before a trial (the ones the arm would refuse, tried last by the episode).
            left = set(self.remaining)
            self.fallback.exclude([i for i in range(len(self.exploration.point.candidates)) if i not in left])
        choice = self.fallback.next()
        assert choice is not None  # it has every candidate still untried
        return choice

    def learn(self, index: int, after: State) -> None:
        self._tried.append(index)
        if self.fallback is not None:
            self.fallback.observe(index, after)
