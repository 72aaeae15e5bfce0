"""The baseline orderings: coverage, case-based reuse, trial and error, uncertainty, the learned policy.

They run on one real failure point (scenario2's, reached through the Gymnasium
environment on a fresh store, with its world model fitted on no trials); what stands in
for physics is which candidates "resolve" (none, unless a test says so).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from llcps.cps.orderings import ORDERINGS, get_ordering  # noqa: E402
from llcps.cps.orderings.base import Exploration, Ordering  # noqa: E402
from llcps.cps.orderings.case_based import CaseBased, parse_failure, role_atoms  # noqa: E402
from llcps.cps.orderings.trial_and_error import TrialAndError  # noqa: E402
from llcps.cps.orderings.uncertainty import Uncertainty  # noqa: E402
from llcps.domain import State  # noqa: E402
from llcps.errors import LlcpsError  # noqa: E402

BASELINES = ("coverage", "case-based", "trial-and-error", "uncertainty", "rl")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from llcps.gym import ExploreEnv

    env = ExploreEnv("scenario2", db=str(tmp_path_factory.mktemp("orderings") / "o.db"), budget=20)
    env.reset(seed=0)
    yield env
    env.close()


def _exploration(env: Any, seed: int = 0) -> Exploration:
    point = env._site_of(0).point
    return Exploration(
        model=env._world_model(), point=point, measure="goal-directed", seed=seed, store=env.store, branch=env.branch
    )


def _run(ordering: Ordering, steps: int, resolving: frozenset[int] = frozenset()) -> list[int]:
    tried: list[int] = []
    while len(tried) < steps and (index := ordering.next()) is not None:
        tried.append(index)
        if index in resolving:
            break
        ordering.observe(index, State())
    return tried


@pytest.fixture(scope="module")
def policy_stored(site: Any) -> None:
    """An (untrained, seeded) policy stored on the branch, for the rl ordering."""
    import torch

    from llcps.cps.policy import POLICY_NAME, export_policy, new_policy

    torch.manual_seed(0)
    artifact = export_policy(new_policy(), hidden=(32, 32), info={"budget": 20})
    site.store.save_world_model(branch=site.branch, name=POLICY_NAME, seed=0, watermark=0, artifact=artifact.data, meta=artifact.meta)


def test_the_baselines_are_registered() -> None:
    assert set(BASELINES) <= set(ORDERINGS)
    for name in BASELINES:
        assert get_ordering(name).ordering_class().name == name


@pytest.mark.parametrize("name", BASELINES)
def test_the_same_seed_gives_the_same_order_and_no_candidate_twice(name: str, site: Any, policy_stored: None) -> None:
    runs = [_run(get_ordering(name)(_exploration(site, seed=5)), steps=12) for _ in range(2)]
    assert runs[0] == runs[1]
    assert len(set(runs[0])) == len(runs[0]) == 12
    assert all(0 <= i < len(site._site_of(0).point.candidates) for i in runs[0])


def test_thompson_sampling_moves_away_from_a_family_after_its_failures(site: Any) -> None:
    """Over many seeds: how often the favourite family is drawn first, and how often once
    five of its candidates failed."""
    first: Counter[tuple[str, tuple[str, ...]]] = Counter()
    after: Counter[tuple[str, tuple[str, ...]]] = Counter()
    orderings = [TrialAndError(_exploration(site, seed=seed)) for seed in range(150)]
    point = orderings[0].exploration.point
    favourite = max(orderings[0].families, key=lambda k: orderings[0].alpha[k] / (orderings[0].alpha[k] + orderings[0].beta[k]))
    for ordering in orderings:
        spec = point.candidates[ordering.next()]
        first[(spec.action, spec.arguments)] += 1
    for ordering in orderings:
        for index in ordering.families[favourite][:5]:
            ordering.observe(index, State())
        spec = point.candidates[ordering.next()]
        after[(spec.action, spec.arguments)] += 1
    assert after[favourite] < first[favourite] / 2
    # Its posterior mean fell with each failure.
    o = orderings[0]
    assert o.alpha[favourite] / (o.alpha[favourite] + o.beta[favourite]) < 0.5 * (o.alpha[favourite] / (o.alpha[favourite] + o.beta[favourite] - 5))


def test_uncertainty_tries_the_candidate_the_ensemble_disagrees_on_first(site: Any) -> None:
    class Flat(Uncertainty):
        """Every candidate equally probable; the members disagree on candidate 7 alone."""

        def members(self) -> np.ndarray:
            n = len(self.exploration.point.candidates)
            spread = np.full((5, n), 0.3)
            spread[:, 7] = [0.0, 0.2, 0.4, 0.6, 0.8]
            return spread

        def _rank(self) -> None:
            self.probability = np.full(len(self.exploration.point.candidates), 0.3)
            self.score = self.probability + self.disagreement

    ordering = Flat(_exploration(site))
    assert ordering.next() == 7
    # Without the bonus the order is the seeded tie order, and the same seed gives it again.
    assert _run(Flat(_exploration(site, seed=2)), 6) == _run(Flat(_exploration(site, seed=2)), 6)


def test_case_based_tries_a_past_resolving_candidate_first_then_the_default(site: Any) -> None:
    """A past episode on the branch resolved the same failure with a candidate (the first
    from 40 on that the arm would not refuse): a fresh episode tries it first, then the
    default ordering's choices."""
    env = site
    env.reset(seed=0)
    point = env._site_of(0).point
    target = next(i for i in range(40, len(point.candidates)) if i not in point.refused)
    env.step(target)  # stored as a gym trial
    trial_id = env.last_trial_id
    episode_id = env._episode_id
    failure = point.failure
    summary = {"failed_action": failure.step.label, "missing_effects": failure.describe(), "resolving_trial_id": trial_id}
    env.store.finish_episode(episode_id, status="solved", summary=summary)
    env._episode_id = None
    ordering = CaseBased(_exploration(env, seed=1))
    assert ordering.reused[:1] == [target]
    tried = _run(ordering, steps=4)
    assert tried[0] == target
    default = get_ordering(ORDERINGS.default)(_exploration(env, seed=1))
    default.exclude([target])
    assert tried[1:] == _run(default, steps=3)
    # A fresh store has no past: the default order from the first trial.
    assert CaseBased(Exploration(model=env._world_model(), point=point, measure="goal-directed", seed=1)).reused == []


def test_once_its_cases_are_spent_case_based_never_chooses_what_was_excluded(site: Any) -> None:
    """The episode excludes what the arm would refuse before the first trial; the default
    ordering case-based falls back on must leave those out too (it chose one, and the
    episode's observe of a candidate the ordering no longer had failed)."""
    env = site
    env.reset(seed=0)
    point = env._site_of(0).point
    target = next(i for i in range(40, len(point.candidates)) if i not in point.refused)
    env.step(target)
    summary = {"failed_action": point.failure.step.label, "missing_effects": point.failure.describe(), "resolving_trial_id": env.last_trial_id}
    env.store.finish_episode(env._episode_id, status="solved", summary=summary)
    env._episode_id = None
    default = get_ordering(ORDERINGS.default)(_exploration(env, seed=1))
    default.exclude([target])
    excluded = _run(default, steps=3)  # what the default would choose next
    ordering = CaseBased(_exploration(env, seed=1))
    ordering.exclude(excluded)
    tried = _run(ordering, steps=6)
    assert tried[0] == target and len(tried) == 6
    assert not set(tried) & set(excluded)


def test_a_stored_failure_parses_into_role_atoms() -> None:
    parsed = parse_failure("(push can bin)", "(push can bin) failed: missing (in can bin) (near can bin); still (on can table)")
    assert parsed is not None
    operator, args, atoms = parsed
    assert (operator, args) == ("push", ("can", "bin"))
    assert role_atoms(atoms, args) == {(("in", "a0", "a1"), True), (("near", "a0", "a1"), True), (("on", "a0", "o"), False)}
    # The same failure on other entities is the same case.
    other = parse_failure("(push cup box)", "(push cup box) failed: missing (in cup box) (near cup box); still (on cup shelf)")
    assert other is not None and role_atoms(other[2], other[1]) == role_atoms(atoms, args)
    for bad in [(None, "x"), ("(push a b)", "nonsense"), ("(push a b)", "(push a b) failed: maybe (in a b)"), ("()", "(x) failed: missing (a)")]:
        assert parse_failure(*bad) is None


def test_the_rl_ordering_follows_the_policy_and_needs_one(site: Any, policy_stored: None, tmp_path: Path) -> None:
    ordering = get_ordering("rl")(_exploration(site))
    probs = ordering.probabilities()
    assert ordering.next() == int(np.argmax(probs))
    from llcps.store import Store

    with Store.open(str(tmp_path / "empty.db"), create=True) as empty:
        x = _exploration(site)
        with pytest.raises(LlcpsError, match="no trained policy"):
            get_ordering("rl")(Exploration(model=x.model, point=x.point, measure=x.measure, seed=0, store=empty, branch="main"))


def test_coverage_meets_every_action_argument_pair_of_a_real_failure_point_before_any_twice(site: Any) -> None:
    exploration = _exploration(site, seed=3)
    point = exploration.point
    pairs = {(c.action, c.arguments) for c in point.candidates}
    tried = _run(get_ordering("coverage")(exploration), steps=len(pairs) + 1)
    met = [(point.candidates[i].action, point.candidates[i].arguments) for i in tried]
    assert len(set(met[:-1])) == len(pairs) and met[-1] in pairs
