"""The goal-aware outcome: role encoding, every model's goal head, the goal-directed
measure, and the episode evidence that drops a failing family.

Training data is the seeded toy of ``llcps.models.synthetic`` (one learnable relation:
``place_in_container(x, c)`` makes ``(in x c)``, nothing else puts anything in anything).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from llcps.cps.candidates import enumerate_candidates
from llcps.domain import ACTIONS, ControllerParams, EntityFeatures, fluent
from llcps.trial_records import Body, Outcome, TrialChange, TrialRecord, TrialSpec
from llcps.errors import LlcpsError
from llcps.models import WORLD_MODELS, load_world_model, make_world_model
from llcps.models.goal import family_scale, joint_probability
from llcps.models.measures import rank
from llcps.models.families import action_sign_of, action_sign_of_stratum, action_stratum_of, family_keys
from llcps.models.relational import (
    GOAL_FEATURES,
    N_GOAL_FEATURES,
    ExampleTable,
    GoalQuery,
    encode_queries,
    trial_examples,
)
from llcps.models.synthetic import synthetic_changes, synthetic_trials

MODELS = list(WORLD_MODELS)
LEARNED = [name for name in MODELS if name != "random"]
TARGET = ("in", "entity0", "entity4")


def scene() -> tuple[Body, ...]:
    """Two objects, a container on the table, the table, the floor and a wall."""
    return (
        Body("cube", "object", "box", (0.37, -0.33, 0.0), (0.43, -0.27, 0.06), (0.4, -0.3, 0.03)),
        Body("ball", "object", "sphere", (0.37, 0.17, 0.0), (0.43, 0.23, 0.06), (0.4, 0.2, 0.03)),
        Body("bucket", "container", "cylinder", (0.27, -0.72, -0.45), (0.53, -0.46, -0.21), (0.4, -0.59, -0.33)),
        Body("table", "table", None, (-0.3, -0.45, -0.45), (1.05, 0.45, 0.0), (0.375, 0.0, -0.225)),
        Body("floor", "floor", None, (-3.0, -3.0, -0.45), (3.0, 3.0, -0.45), (0.0, 0.0, -0.45)),
        Body("wall", "fixture", None, (-0.3, -0.45, 0.0), (1.05, -0.43, 0.07), (0.375, -0.44, 0.035)),
    )


def value(row: np.ndarray, name: str) -> float:
    return float(row[GOAL_FEATURES.index(name)])


# ------------------------------------------------------------------ stored change and roles
def test_a_hand_made_change_and_its_role_encoding():
    before = {
        fluent("on", "cube", "table"),
        fluent("touching", "cube", "table"),
        fluent("touching", "cube", "wall"),
        fluent("on", "ball", "table"),
        fluent("visible", "cube"),
    }
    after = (before - {fluent("on", "cube", "table"), fluent("touching", "cube", "table")}) | {
        fluent("in", "cube", "bucket"),
        fluent("touching", "bucket", "cube"),
    }
    change = TrialChange.between(before, after, scene())
    assert change.added == {("in", "cube", "bucket"), ("touching", "bucket", "cube")}
    assert change.deleted == {("on", "cube", "table"), ("touching", "cube", "table")}
    assert change.after == frozenset(after)
    spec = TrialSpec("place_in_container", ("cube", "bucket"), ControllerParams(0.4, 0.15, "left"))
    record = TrialRecord(
        branch="main", source="exploration", spec=spec, features=(), outcome=Outcome(), solved=True,
        sim_steps=1, wall_seconds=0.0, seed=3, id=7,
    )  # fmt: skip
    examples = trial_examples(record, change)
    rows = {}
    from llcps.models.relational import ROLES, Scene, _Candidate, _row

    sc = Scene(change.bodies)
    cand = _Candidate(spec, sc)
    for atom, add in [(("in", "cube", "bucket"), True), (("on", "cube", "table"), False), (("touching", "ball", "wall"), True)]:
        out = np.zeros(N_GOAL_FEATURES)
        _row(cand, sc, atom, add, out)
        rows[atom] = out
    in_row = rows[("in", "cube", "bucket")]
    assert value(in_row, "role1=arg1") == 1 and value(in_row, "role2=arg2") == 1 and value(in_row, "add") == 1
    assert value(in_row, "predicate=in") == 1 and value(in_row, "action=place_in_container") == 1
    # body 2 (the bucket) lies below and to the right (-y) of argument 1; the place moves toward it
    assert value(in_row, "body2_dz") < -0.3 and value(in_row, "body2_dy") < -0.2
    assert value(in_row, "motion_cos") == pytest.approx(1.0)
    on_row = rows[("on", "cube", "table")]
    assert value(on_row, "role2=table") == 1 and value(on_row, "add") == 0
    wall_row = rows[("touching", "ball", "wall")]
    assert value(wall_row, "role1=object") == 1 and value(wall_row, "role2=fixture") == 1
    assert sum(value(in_row, f"role1={r}") for r in ROLES) == 1
    # the examples of the stored trial: every changed atom is a positive, labelled as the change says
    features, labels = examples.features, examples.labels
    predicate_in = features[:, GOAL_FEATURES.index("predicate=in")] == 1
    assert labels[predicate_in & (features[:, GOAL_FEATURES.index("role1=arg1")] == 1)].tolist() == [1]
    assert labels.sum() == len(change.added) + len(change.deleted)
    assert examples.weights.min() >= 1.0 and np.all(examples.trial_ids == 7)


def test_names_do_not_matter_only_roles_and_geometry():
    bodies = scene()
    renamed = {"cube": "thing_a", "ball": "thing_b", "bucket": "pail", "wall": "fence"}
    other = tuple(replace(b, name=renamed.get(b.name, b.name)) for b in bodies)
    spec = TrialSpec("push", ("cube",), ControllerParams(1.0, 0.3, "left"))
    spec2 = TrialSpec("push", ("thing_a",), ControllerParams(1.0, 0.3, "left"))
    q1 = GoalQuery.from_missing([spec], missing_add=[("in", "cube", "bucket")], missing_del=[], bodies=bodies)
    q2 = GoalQuery.from_missing([spec2], missing_add=[("in", "thing_a", "pail")], missing_del=[], bodies=other)
    assert np.array_equal(encode_queries(q1), encode_queries(q2))


def test_a_query_naming_an_unknown_body_is_refused():
    spec = TrialSpec("push", ("cube",), ControllerParams(1.0, 0.3, "left"))
    with pytest.raises(LlcpsError, match="does not have"):
        encode_queries(GoalQuery.from_missing([spec], missing_add=[("in", "cube", "nope")], missing_del=[], bodies=scene()))
    with pytest.raises(LlcpsError, match="predicate"):
        encode_queries(GoalQuery.from_missing([spec], missing_add=[("glued", "cube")], missing_del=[], bodies=scene()))


# ------------------------------------------------------------------------------ the measure
goal_arrays = st.integers(1, 30).flatmap(
    lambda n: st.integers(1, 3).flatmap(
        lambda k: arrays(np.float64, (n, k), elements=st.one_of(st.sampled_from([0.0, 0.5, 1.0]), st.floats(0.0, 1.0)))
    )
)


@settings(max_examples=200, deadline=None)
@given(goal=goal_arrays, seed=st.integers(0, 2**32 - 1))
def test_goal_directed_ranks_a_likelier_candidate_first(goal, seed):
    proba = np.full((len(goal), 6), 0.5)
    order = rank(proba, "goal-directed", seed=seed, goal=goal).tolist()
    joint = joint_probability(goal)
    position = {c: i for i, c in enumerate(order)}
    for a in range(len(goal)):
        for b in range(len(goal)):
            # Equal products up to rounding (the same factors in another order) are ties:
            # the measure sums logarithms, so either may come first.
            if joint[a] > joint[b] * (1 + 1e-9) and joint[a] > 1e-12 * 10:
                assert position[a] < position[b]
    assert np.array_equal(order, rank(proba, "goal-directed", seed=seed, goal=goal.copy()))


def test_goal_predictions_must_be_probabilities():
    proba = np.full((2, 6), 0.5)
    with pytest.raises(LlcpsError, match="goal predictions"):
        rank(proba, "goal-directed", seed=0, goal=np.array([[0.5], [1.5]]))
    with pytest.raises(LlcpsError, match="shape"):
        rank(proba, "goal-directed", seed=0, goal=np.array([[0.5]]))


# ------------------------------------------------------------------------------ the models
@pytest.fixture(scope="module")
def toy():
    records = synthetic_trials(200, seed=11)
    return records, synthetic_changes(records, seed=11)


@pytest.fixture(scope="module")
def query():
    test = synthetic_trials(1, seed=99, start_id=1000)
    bodies = next(iter(synthetic_changes(test, seed=5).values())).bodies
    kinds = {b.name: b.kind for b in bodies if b.is_entity}
    candidates = enumerate_candidates(failed=None, entities=kinds)
    return GoalQuery.from_missing(candidates, missing_add=[TARGET], missing_del=[], bodies=bodies)


def four(records):
    return [next(r for r in records if r.spec.action == action) for action in ACTIONS]


@pytest.fixture(scope="module")
def fitted(toy):
    cache = {}

    def get(name, size, seed=0):
        if (name, size, seed) not in cache:
            records, changes = toy
            chosen = records if size == 200 else four(records)
            cache[name, size, seed] = make_world_model(name, seed).fit(chosen, changes)
        return cache[name, size, seed]

    return get


@pytest.mark.parametrize("size", [4, 200])
@pytest.mark.parametrize("name", MODELS)
def test_every_model_predicts_goal_probabilities(fitted, query, name, size):
    model = fitted(name, size)
    p = model.predict_goal(query)
    assert p.shape == (len(query.candidates), 1)
    assert np.all(np.isfinite(p)) and p.min() >= 0.0 and p.max() <= 1.0
    again = fitted(name, size, seed=0).predict_goal(query)
    assert np.array_equal(p, again)


@pytest.mark.parametrize("name", MODELS)
def test_same_seed_same_order_and_the_artifact_predicts_the_same(fitted, toy, query, name):
    records, changes = toy
    first = make_world_model(name, 3).fit(records, changes)
    second = make_world_model(name, 3).fit(records, changes)
    order = rank(np.full((len(query.candidates), 6), 0.5), "goal-directed", seed=3, goal=first.predict_goal(query))
    assert np.array_equal(order, rank(np.full((len(query.candidates), 6), 0.5), "goal-directed", seed=3, goal=second.predict_goal(query)))
    artifact, meta = first.to_artifact()
    loaded = load_world_model(artifact, meta, seed=3)
    assert np.allclose(loaded.predict_goal(query), first.predict_goal(query), atol=1e-6)


@pytest.mark.parametrize("name", LEARNED)
def test_a_learnable_relation_ranks_its_candidates_first(fitted, query, name):
    p = fitted(name, 200).predict_goal(query)
    order = rank(np.full((len(p), 6), 0.5), "goal-directed", seed=0, goal=p)
    wanted = {i for i, c in enumerate(query.candidates) if c.action == "place_in_container" and c.arguments == TARGET[1:]}
    assert len(wanted) == 36
    assert set(order[: len(wanted)].tolist()) == wanted


@pytest.mark.parametrize("size", [4, 200])
@pytest.mark.parametrize("name", LEARNED)
def test_what_k_claims_is_mixed_in_where_the_learner_saw_nothing(fitted, query, name, size):
    """A candidate whose action K claims makes the atom gets the novelty mix of certainty:
    (1 - e) p + e instead of (1 - e) p + e r; nothing else moves."""
    from llcps.models.goal import NOVELTY_MIX

    model = fitted(name, size)
    pushes = {c for c in query.candidates if c.action == "push" and c.arguments == TARGET[1:2]}
    assert len(pushes) == 36
    claimed = GoalQuery.from_missing(
        query.candidates, missing_add=[TARGET], missing_del=[], bodies=query.bodies,
        claims=lambda spec, atom, add: spec in pushes and atom == TARGET and add,
    )  # fmt: skip
    before, after = model.predict_goal(query)[:, 0], model.predict_goal(claimed)[:, 0]
    lifted = np.array([c in pushes for c in query.candidates])
    assert np.allclose(after[~lifted], before[~lifted])
    assert np.all(after[lifted] > before[lifted])
    assert np.allclose(after[lifted] - before[lifted], after[lifted][0] - before[lifted][0])  # one shift for all
    assert after[lifted].min() >= NOVELTY_MIX - 1e-12


@pytest.mark.parametrize("learner", ["nb", "logreg"])
def test_a_setting_one_controller_needs_is_not_carried_over_to_another(learner):
    """Slow grasps empty the bucket, fast pushes tip it over, slow pushes do nothing: the
    learners without interactions learn each controller's settings apart (a learner
    pooled over controllers ranks the slow push first, as the slow grasps outnumber)."""
    from llcps.models.baselines import LogisticGoal
    from llcps.models.goal import StratifiedLearner
    from llcps.models.naive_bayes import NaiveBayesGoal

    atom = ("in", "cube", "bucket")
    specs = {
        (action, rate): TrialSpec(action, args, ControllerParams(rate, 0.15, "left"))
        for action, args in (("remove_from_container", ("cube", "bucket")), ("push", ("bucket",)))
        for rate in (0.1, 1.0)
    }
    query = GoalQuery.from_missing(list(specs.values()), missing_add=[], missing_del=[atom], bodies=scene())
    rows = dict(zip(specs, encode_queries(query)))
    counts = {("remove_from_container", 0.1): (30, 1), ("remove_from_container", 1.0): (10, 0), ("push", 1.0): (5, 1), ("push", 0.1): (20, 0)}
    features = np.concatenate([np.repeat(rows[key][None], n, axis=0) for key, (n, _) in counts.items()])
    labels = np.concatenate([np.full(n, label, dtype=np.uint8) for n, label in counts.values()])
    make = {"nb": NaiveBayesGoal, "logreg": LogisticGoal}[learner]
    stratified = StratifiedLearner(0, make)
    stratified.fit(features, labels, np.ones(len(labels)))
    slow, fast = stratified.predict(np.stack([rows[("push", 0.1)], rows[("push", 1.0)]]))
    assert fast > 0.5 > slow
    if learner == "nb":
        pooled = make(0)
        pooled.fit(features, labels, np.ones(len(labels)))
        pooled_slow, pooled_fast = pooled.predict(np.stack([rows[("push", 0.1)], rows[("push", 1.0)]]))
        assert pooled_slow > pooled_fast  # what the strata are for


@pytest.mark.parametrize("learner", ["nb", "logreg"])
def test_a_change_a_controller_never_made_backs_off_to_its_other_changes(learner):
    """No push in training took the cube out of the bucket (five tried), but fast pushes
    ended the cube's (on cube table) and slow ones did not: for the missing deletion of
    (in cube bucket) the learners without interactions rank the fast push first (before
    the back-off, every push of a one-class stratum had one flat rate), and a stratum
    never seen at all gets its (action, sign) stratum's rate."""
    from llcps.models.baselines import LogisticGoal
    from llcps.models.goal import StratifiedLearner
    from llcps.models.naive_bayes import NaiveBayesGoal

    specs = {rate: TrialSpec("push", ("cube",), ControllerParams(rate, 0.15, "left")) for rate in (0.1, 1.0)}

    def rows(atom):
        query = GoalQuery.from_missing(list(specs.values()), missing_add=[], missing_del=[atom], bodies=scene())
        return dict(zip(specs, encode_queries(query)))

    seen, asked = rows(("on", "cube", "table")), rows(("in", "cube", "bucket"))
    counts = {(0.1, "on"): (20, 0), (1.0, "on"): (10, 1), (0.1, "in"): (3, 0), (1.0, "in"): (2, 0)}
    table = {"on": seen, "in": asked}
    features = np.concatenate([np.repeat(table[atom][rate][None], n, axis=0) for (rate, atom), (n, _) in counts.items()])
    labels = np.concatenate([np.full(n, label, dtype=np.uint8) for n, label in counts.values()])
    stratified = StratifiedLearner(0, {"nb": NaiveBayesGoal, "logreg": LogisticGoal}[learner])
    stratified.fit(features, labels, np.ones(len(labels)))
    slow, fast = stratified.predict(np.stack([asked[0.1], asked[1.0]]))
    assert fast > 2 * slow, (slow, fast)
    assert 0.0 <= slow and fast <= 1.0
    arrays = stratified.export()
    again = StratifiedLearner(0, {"nb": NaiveBayesGoal, "logreg": LogisticGoal}[learner])
    again.load(arrays)
    assert np.array_equal(again.predict(np.stack([asked[0.1], asked[1.0]])), np.array([slow, fast]))
    unseen = TrialSpec("push_together", ("cube", "ball"), ControllerParams(1.0, 0.15, "left"))
    query = GoalQuery.from_missing([unseen], missing_add=[], missing_del=[("in", "cube", "bucket")], bodies=scene())
    assert stratified.predict(encode_queries(query))[0] == pytest.approx(0.5)  # no push_together deletion seen: (0 + 1) / (0 + 2)


def test_a_query_s_claims_must_match_its_candidates_and_atoms(query):
    with pytest.raises(ValueError, match="one flag per candidate and atom"):
        GoalQuery(query.candidates[:2], query.atoms, query.bodies, claimed=((True,),))


def failing_trials(query, family, start_id, n, snapshot_id=None):
    """``n`` trials of the candidates in ``family`` that changed nothing (the atom stayed false)."""
    before = frozenset({fluent("on", "entity0", "table")})
    out, changes = [], {}
    for k, index in enumerate(family[:n]):
        spec = query.candidates[index]
        features = tuple(EntityFeatures("box", 0.001, "red", 0.5, 1.0, 0.0, 0.0) for _ in spec.arguments)
        record = TrialRecord(
            branch="main", source="exploration", spec=spec, features=features, outcome=Outcome(), solved=False,
            sim_steps=1, wall_seconds=0.0, seed=0, id=start_id + k, snapshot_id=snapshot_id,
        )  # fmt: skip
        out.append(record)
        changes[record.id] = TrialChange(before, frozenset(), frozenset(), query.bodies, trial_id=record.id)
    return out, changes


@pytest.mark.parametrize("name", LEARNED)
def test_a_family_that_keeps_failing_drops(toy, query, name):
    records, changes = toy
    model = make_world_model(name, 0).fit(records, changes)
    p = model.predict_goal(query)[:, 0]
    family = [i for i in np.argsort(-p, kind="stable") if query.candidates[i].action == "place_in_container"][:36]
    tried, tried_changes = failing_trials(query, family, 10_000, 12)
    model.update(list(records) + tried, {**changes, **tried_changes})
    after = model.predict_goal(query)[:, 0]
    untried = family[12:]
    assert np.all(after[untried] < p[untried])
    others = [i for i in range(len(p)) if query.candidates[i].action != "place_in_container"]
    assert np.allclose(after[others], p[others])  # other families are not touched
    # evidence is kept until the next fit, which starts from all trials again
    model.fit(list(records) + tried, {**changes, **tried_changes})
    assert model.goal.watermark == 10_011


@pytest.mark.parametrize("name", ["nb", "logreg"])
def test_only_trials_from_the_ranked_start_state_are_episode_evidence(toy, query, name):
    """A plan step run from the state a trial left behind says nothing certain about a
    family at the failure point: with ``start`` set, only trials that started there count."""
    records, changes = toy
    p = make_world_model(name, 0).fit(records, changes).predict_goal(query)[:, 0]
    family = [i for i in np.argsort(-p, kind="stable") if query.candidates[i].action == "place_in_container"][:36]
    elsewhere, elsewhere_changes = failing_trials(query, family, 10_000, 6, snapshot_id=2)
    here, here_changes = failing_trials(query, family[6:], 20_000, 6, snapshot_id=1)
    trials, all_changes = list(records) + elsewhere + here, {**changes, **elsewhere_changes, **here_changes}

    def after(start):
        model = make_world_model(name, 0).fit(records, changes)
        return model.update(trials, all_changes, start=start).predict_goal(query)[:, 0]

    untried = family[12:]
    only_here, every_trial = after(1), after(None)
    assert np.all(only_here[untried] < p[untried])  # the trials from the start state count
    assert np.all(every_trial[untried] < only_here[untried])  # the others would have counted too
    only_elsewhere = make_world_model(name, 0).fit(records, changes)
    only_elsewhere.update(list(records) + elsewhere, {**changes, **elsewhere_changes}, start=1)
    assert np.allclose(only_elsewhere.predict_goal(query)[:, 0], p)


@pytest.mark.parametrize("mean_probability", [0.02, 0.1, 0.25, 0.6])
def test_a_family_s_scale_falls_with_failures_but_never_rules_it_out(mean_probability):
    """No evidence leaves a family as the learner said; each failure lowers it; a
    success raises it. The share of a working family's members that change the atom is
    unknown, so a family whose working members are rare is lowered polynomially in its
    failures, not geometrically: after 40 failures it keeps more than a tenth of what it
    had after 20 (a fixed share of one half would keep 2^-20 of it)."""
    assert family_scale(0, 0.0, mean_probability) == pytest.approx(1.0)
    scales = [family_scale(n, 0.0, mean_probability) for n in range(0, 41)]
    assert all(b < a for a, b in zip(scales, scales[1:]))
    assert scales[40] / scales[20] > 0.1
    assert family_scale(3, 1.0, mean_probability) > 1.0


def test_families_are_action_predicate_sign_roles_orientation_and_magnitude(query):
    rows = encode_queries(query)
    coarse, by_orientation, by_magnitude, motion = family_keys(rows)
    settings = [c.params for c in query.candidates]
    actions = [c.action for c in query.candidates]
    for i in range(0, len(rows), 37):
        for j in range(0, len(rows), 41):
            same_args = query.candidates[i].arguments == query.candidates[j].arguments
            if actions[i] == actions[j] and same_args:
                assert coarse[i] == coarse[j]
                assert (by_orientation[i] == by_orientation[j]) == (settings[i].orientation == settings[j].orientation)
                assert (by_magnitude[i] == by_magnitude[j]) == (settings[i].movement_magnitude == settings[j].movement_magnitude)
            if actions[i] == actions[j]:  # the motion: the action and all its settings, whatever the bodies
                assert (motion[i] == motion[j]) == (settings[i] == settings[j])
            if actions[i] != actions[j]:
                assert coarse[i] != coarse[j] and motion[i] != motion[j]
                assert by_orientation[i] != by_orientation[j] and by_magnitude[i] != by_magnitude[j]


def test_each_stratum_backs_off_to_its_own_action_and_sign(toy):
    """The back-off's index of a row's stratum is the row's own (action, sign)."""
    records, changes = toy
    rows = ExampleTable().encode(records, changes).features
    signs = action_sign_of(rows)
    assert len(np.unique(signs)) == 2 * len(ACTIONS)  # every controller, adding and deleting
    assert np.array_equal(action_sign_of_stratum(action_stratum_of(rows)), signs)


@pytest.mark.parametrize("name", ["nb", "logreg"])
def test_a_failed_motion_drops_on_the_action_s_other_bodies(toy, query, name):
    """The same stroke with the same settings from the same start state tends to do the
    same whichever bodies it names: one failure lowers it on the other bodies too, more
    than it lowers any other motion of the same family."""
    records, changes = toy
    model = make_world_model(name, 0).fit(records, changes)
    p = model.predict_goal(query)[:, 0]
    coarse, *_, motion = family_keys(encode_queries(query))
    pushes = [i for i, c in enumerate(query.candidates) if c.action == "push_together"]
    tried = pushes[0]
    same_motion = [i for i in pushes if coarse[i] != coarse[tried] and motion[i] == motion[tried]]
    assert same_motion
    failed, failed_changes = failing_trials(query, [tried], 10_000, 1)
    model.update(list(records) + failed, {**changes, **failed_changes})
    ratio = model.predict_goal(query)[:, 0] / p
    for i in same_motion:
        assert ratio[i] < 1.0
        siblings = [j for j in pushes if coarse[j] == coarse[i] and motion[j] != motion[i]]
        assert siblings and np.all(ratio[i] < ratio[siblings])


@pytest.mark.parametrize("name", ["nb", "logreg"])
def test_a_change_of_an_atom_not_asked_is_no_episode_evidence(toy, query, name):
    """A placement that put another object into the container says the family can
    work, but not that it can put in the object the novelty stopped: asked for
    ``TARGET`` alone, that success moves nothing of the family's other settings, where
    without ``asked`` it raises them. The trial's failures still count: what it left as
    it was is kept."""
    records, changes = toy
    p = make_world_model(name, 0).fit(records, changes).predict_goal(query)[:, 0]
    coarse, *_, motion = family_keys(encode_queries(query))
    placements = [i for i, c in enumerate(query.candidates) if c.action == "place_in_container" and c.arguments == TARGET[1:]]
    other = replace(query.candidates[placements[0]], arguments=("entity1", TARGET[2]))
    assert other.arguments != TARGET[1:] and ("in", *other.arguments) != TARGET
    moved, moved_changes = failing_trials(query, [placements[0]], 10_000, 1)
    moved = [replace(moved[0], spec=other)]
    before = moved_changes[10_000].before
    moved_changes = {10_000: TrialChange(before, frozenset({fluent("in", *other.arguments)}), frozenset(), query.bodies, trial_id=10_000)}
    trials, all_changes = list(records) + moved, {**changes, **moved_changes}
    elsewhere = [i for i in placements if coarse[i] == coarse[placements[0]] and motion[i] != motion[placements[0]]]
    assert elsewhere

    def after(asked):
        model = make_world_model(name, 0).fit(records, changes)
        return model.update(trials, all_changes, asked=asked).predict_goal(query)[:, 0]

    assert np.all(after(None)[elsewhere] > p[elsewhere])  # any atom: the success is the family's
    assert np.allclose(after({(TARGET, True)})[elsewhere], p[elsewhere])  # asked: it is not evidence
    # the asked atom itself, made by the trial, is evidence as before
    made = {10_000: replace(moved_changes[10_000], added=frozenset({fluent(*TARGET)}))}
    model = make_world_model(name, 0).fit(records, changes)
    model.update(list(records) + [replace(moved[0], spec=query.candidates[placements[0]])], {**changes, **made}, asked={(TARGET, True)})
    assert np.all(model.predict_goal(query)[:, 0][elsewhere] > p[elsewhere])
