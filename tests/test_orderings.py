"""Exploration orderings (llcps.cps.orderings): the paper's ranking, coverage and the hedge.

The orderings run here on synthetic failure points: the candidates of a small scene, a
fixed probability of resolving the novelty per candidate stands in for the world model,
and a set of resolving candidates for physics, so the hedge's guarantee can be checked
over many seeds and layouts.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from llcps.cps.ranking import Ranking
from llcps.cps.orderings import ORDERINGS, get_ordering
from llcps.cps.candidates import enumerate_candidates
from llcps.cps.orderings.base import Exploration, resolving_pick
from llcps.cps.orderings.coverage import SpreadWalk, spread
from llcps.cps.orderings.hedged import MAX_MODEL_SHARE, Hedged
from llcps.cps.orderings.ranked import Ranked
from llcps.domain import State


def _synthetic(base, probability: np.ndarray, *, families: np.ndarray | None = None):
    """``base`` ranking by fixed probabilities; a failed trial of a family halves the
    family's probabilities (a stand-in for the goal head's episode evidence)."""

    class Synthetic(base):  # type: ignore[misc, valid-type]
        def random_side(self) -> SpreadWalk:
            candidates = self.exploration.point.candidates
            permutation = [int(i) for i in _permutation(len(candidates), self.exploration.seed)]
            return SpreadWalk(candidates, permutation, self.exploration.point.state)

        def rank(self) -> Ranking:
            p = probability.copy()
            if families is not None:
                for index in getattr(self, "taken", []):
                    p[families == families[index]] *= 0.5
            chosen = list(self.remaining)
            score = p[chosen]
            order = np.lexsort((np.arange(len(chosen)), -score))
            return Ranking(
                order=[chosen[i] for i in order],
                indices=chosen,
                score=score,
                outcome=np.zeros((len(chosen), 6)),
                goal=score[:, None],
            )

    return Synthetic


#: The candidates of a scene of three objects and a container: 22 action-argument pairs of 36 settings.
CANDIDATES = tuple(enumerate_candidates(failed=None, entities={"a": "object", "b": "object", "c": "object", "d": "container"}))


def _permutation(n: int, seed: int) -> np.ndarray:
    """Random order's permutation (a stand-in for the random model's ranking)."""
    return np.random.default_rng(seed).permutation(n)


def _exploration(n: int, seed: int) -> Exploration:
    point = SimpleNamespace(candidates=CANDIDATES[:n], subgoals=(), relocations=frozenset(), state=State())
    return Exploration(model=None, point=point, measure="goal-directed", seed=seed)  # type: ignore[arg-type]


def _run(ordering, resolving: set[int]) -> list[int]:
    """The candidates tried until one in ``resolving`` (included), or every one."""
    tried = []
    while (index := ordering.next()) is not None:
        tried.append(index)
        if index in resolving:
            break
        ordering.observe(index, State())
    return tried


def test_the_registry_names_both_orderings_hedged_is_the_default_and_ranked_the_papers():
    from llcps.cps.orderings import PAPER_ORDERING

    assert set(ORDERINGS) >= {"ranked", "hedged"}
    assert ORDERINGS.default == "hedged" and PAPER_ORDERING == "ranked"
    assert get_ordering("hedged").ordering_class() is Hedged


def test_ranked_tries_the_candidates_best_first():
    p = np.array([0.1, 0.9, 0.5, 0.3])
    ordering = _synthetic(Ranked, p)(_exploration(4, seed=0))
    assert _run(ordering, resolving=set()) == [1, 2, 3, 0]


def test_the_hedge_is_a_function_of_the_seed():
    p = np.random.default_rng(1).random(200)
    runs = [_run(_synthetic(Hedged, p)(_exploration(200, seed=seed)), resolving={7}) for seed in (3, 3, 4)]
    assert runs[0] == runs[1]
    assert runs[0] != runs[2]


def test_the_ranking_inside_the_hedge_learns_from_its_own_trials_only():
    rng = np.random.default_rng(2)
    p, families = 0.1 * rng.random(300), rng.integers(0, 12, 300)
    hedge = _synthetic(Hedged, p, families=families)(_exploration(300, seed=0))
    tried = _run(hedge, resolving=set())
    model_side = [index for index, pick in zip(tried, hedge.picks) if pick == "model"]
    assert hedge.taken == model_side
    assert 10 < len(model_side) < len(tried) == 300
    # Each model pick is the best untried candidate under the evidence of the model's own picks.
    for j, index in enumerate(model_side[:40]):
        untried = [i for i in range(300) if i not in tried[: tried.index(index)]]
        halved = p * 0.5 ** np.array([sum(families[t] == families[i] for t in model_side[:j]) for i in range(300)])
        assert index == max(untried, key=lambda i: (halved[i], -untried.index(i)))


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(20, 400),
    resolvers=st.integers(1, 8),
    wrong=st.floats(0.05, 0.95),
    confident=st.booleans(),
)
def test_the_hedge_reaches_a_resolver_within_its_bound_of_random_order_when_the_model_points_away(
    seed, n, resolvers, wrong, confident
):
    """The model ranks a family that never resolves first (``wrong`` of the candidates,
    sure of it or not) and the resolving candidates last: the episode still ends by trial
    P / (1 - MAX_MODEL_SHARE), P the first resolver's position in the random order."""
    rng = np.random.default_rng([seed, 1])
    resolving = {int(i) for i in rng.choice(n, size=min(resolvers, n), replace=False)}
    p = np.where(rng.random(n) < wrong, 0.9 if confident else 0.02, 0.01)
    p[list(resolving)] = 0.001
    hedge = _synthetic(Hedged, p, families=(p * 1000).astype(int))(_exploration(n, seed))
    tried = _run(hedge, resolving)
    assert tried[-1] in resolving
    position = 1 + min(hedge.random.order.index(i) for i in resolving)
    assert len(tried) <= position / (1.0 - MAX_MODEL_SHARE)


def test_a_model_sure_of_what_fails_loses_its_share_and_the_hedge_costs_about_random_order():
    """Averaged over layouts: a model sure of 100 candidates that all fail, in 400 with 4
    resolvers, costs the ranking about 100 trials; the hedge stays within a fifth of random
    order's expected position (N + 1) / (k + 1) = 80.2."""
    n, k = 400, 4
    costs, ranked_costs = [], []
    for seed in range(200):
        order = np.random.default_rng([seed, 1]).permutation(n)  # the layout, apart from the random side's stream
        wrong, resolving = order[:100], {int(i) for i in order[100 : 100 + k]}
        p = np.full(n, 0.01)
        p[wrong] = 0.6
        p[list(resolving)] = 0.001
        costs.append(len(_run(_synthetic(Hedged, p)(_exploration(n, seed)), resolving)))
        ranked_costs.append(len(_run(_synthetic(Ranked, p)(_exploration(n, seed)), resolving)))
    expected_random = (n + 1) / (k + 1)
    assert np.mean(ranked_costs) > 1.5 * expected_random
    assert np.mean(costs) <= 1.2 * expected_random


@pytest.mark.parametrize("k", [1, 3, 10])
def test_where_the_model_is_right_the_hedge_tries_its_kth_best_by_trial_2k_minus_1_and_its_first_second(k):
    n = 300
    p = np.linspace(0.5, 0.01, n)  # candidate i is the model's (i+1)-th best
    hedge = _synthetic(Hedged, p)(_exploration(n, seed=5))
    tried = _run(hedge, resolving={k - 1})
    assert hedge.picks[0] == "random"
    assert len(tried) <= max(2 * k - 1, 2) or hedge.beliefs[-1] < MAX_MODEL_SHARE


def _first(order, resolving: set[int]) -> int:
    """The position (from 1) of the first resolving candidate in ``order``."""
    return 1 + next(k for k, i in enumerate(order) if i in resolving)


def _pair(index: int) -> tuple[str, tuple[str, ...]]:
    return CANDIDATES[index].action, CANDIDATES[index].arguments


def test_coverage_tries_every_action_argument_pair_before_any_twice_and_each_pairs_settings_in_turn():
    order = spread(CANDIDATES, [int(i) for i in _permutation(len(CANDIDATES), 3)])
    assert sorted(order) == list(range(len(CANDIDATES)))
    pairs = [_pair(i) for i in order]
    assert len(set(pairs[:22])) == 22 and len(set(pairs[22:44])) == 22
    for pair in set(pairs):
        mine = [CANDIDATES[i].params for i in order if _pair(i) == pair]
        assert len({p.orientation for p in mine[:4]}) == 4
        assert len({p.movement_magnitude for p in mine[:3]}) == 3 and len({p.rate for p in mine[:3]}) == 3
    assert order[0] == int(_permutation(len(CANDIDATES), 3)[0])  # the permutation decides among equals
    assert spread(CANDIDATES, [int(i) for i in _permutation(len(CANDIDATES), 4)]) != order


def test_coverage_meets_a_resolving_pair_sooner_than_random_order_and_a_scattered_set_about_as_soon():
    """Over layouts: every setting of one action-argument pair resolves (random order's
    expected position (N + 1) / (36 + 1) = 21.4; coverage's (22 + 1) / 2 = 11.5), or 36
    candidates anywhere do (21.4 for both)."""
    n = len(CANDIDATES)
    pairs = sorted({_pair(i) for i in range(n)})
    met: dict[str, list[int]] = {"clustered": [], "clustered, random": [], "scattered": [], "scattered, random": []}
    for seed in range(300):
        permutation = [int(i) for i in _permutation(n, seed)]
        order = spread(CANDIDATES, permutation)
        rng = np.random.default_rng([seed, 1])
        pair = pairs[int(rng.integers(len(pairs)))]
        clustered = {i for i in range(n) if _pair(i) == pair}
        scattered = {int(i) for i in rng.choice(n, size=36, replace=False)}
        met["clustered"].append(_first(order, clustered))
        met["clustered, random"].append(_first(permutation, clustered))
        met["scattered"].append(_first(order, scattered))
        met["scattered, random"].append(_first(permutation, scattered))
    mean = {key: float(np.mean(value)) for key, value in met.items()}
    assert mean["clustered"] <= 12.5 and max(met["clustered"]) <= 22
    assert mean["clustered, random"] >= 18.0
    assert mean["scattered"] <= 1.15 * (n + 1) / 37


@pytest.mark.parametrize(
    ("summary", "pick"),
    [
        ({"exploration_trials": 3, "ordering_trace": {"picks": ["model", "random", "model"], "beliefs": [0.5, 0.4, 0.3]}}, "model"),
        ({"exploration_trials": 2, "ordering_trace": {"picks": ["model", "random"]}}, "random"),
        ({"exploration_trials": 3, "ordering_trace": {"picks": ["model", "random"]}}, None),  # the last trial was no pick of the ordering
        ({"exploration_trials": 1}, None),  # another ordering, or a summary from before the trace
        ({"exploration_trials": 1, "ordering_trace": "model"}, None),
        ({"exploration_trials": 1, "ordering_trace": {"picks": [7]}}, None),
        ({"exploration_trials": "1", "ordering_trace": {"picks": ["model"]}}, None),
        ({"exploration_trials": 1, "ordering_trace": {"picks": ["x" * 10_000]}}, None),
        ({"exploration_trials": 1, "ordering_trace": {"picks": [""]}}, None),
        ({"exploration_trials": 1, "ordering_trace": {"picks": ["mo\ndel"]}}, None),
    ],
)
def test_the_resolving_pick_is_read_from_an_untrusted_summary(summary: dict, pick: str | None) -> None:
    assert resolving_pick(summary) == pick


def test_the_spread_walk_puts_off_a_pair_whose_trial_changed_nothing():
    """After a trial of pair X that changed no atom, every other pair's next member comes
    before X's next; without such a trial the walk is spread's order."""
    permutation = [int(i) for i in _permutation(len(CANDIDATES), 5)]
    start = State()
    walk = SpreadWalk(CANDIDATES, permutation, start)
    assert walk.order == spread(CANDIDATES, permutation)
    untried = set(range(len(CANDIDATES)))

    def walk_on() -> int:
        index = walk.next_untried(untried)
        untried.discard(index)
        return index

    first = walk_on()
    walk.learn(first, start)  # it changed nothing
    pairs = []
    while not pairs or pairs[-1] != _pair(first):
        pairs.append(_pair(walk_on()))
    # the first pair counts as met twice: the 21 others are each met about twice before it comes back
    assert len(set(pairs[:-1])) == 21 and len(pairs) - 1 >= 2 * 21 - 1
    assert sorted(walk.order) == list(range(len(CANDIDATES)))
