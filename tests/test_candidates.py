from __future__ import annotations

import pytest

from llcps.cps.candidates import Grid, argument_tuples, enumerate_candidates, focused_count
from llcps.domain import ACTION_ARITY, ACTIONS, ControllerParams
from llcps.trial_records import TrialSpec

ENTITIES = {"cube": "object", "ball": "object", "bucket": "container"}


def test_argument_tuples_respect_kinds_and_distinctness() -> None:
    assert argument_tuples("push", ENTITIES) == [("ball",), ("bucket",), ("cube",)]
    assert argument_tuples("place_in_container", ENTITIES) == [("ball", "bucket"), ("cube", "bucket")]
    pairs = argument_tuples("push_together", ENTITIES)
    assert len(pairs) == 6 and all(a != b for a, b in pairs)


def test_failed_action_comes_first_and_is_excluded() -> None:
    failed = TrialSpec("push", ("cube",), ControllerParams(0.4, 0.15, "left"))
    candidates = enumerate_candidates(failed=failed, entities=ENTITIES)
    grid = Grid()
    assert failed not in candidates
    assert focused_count(candidates, failed) == grid.size - 1
    # after the focused block: the failed action on other entities, then other actions
    rest = candidates[grid.size - 1 :]
    first_other = next(i for i, spec in enumerate(rest) if spec.action != "push")
    assert all(spec.action == "push" for spec in rest[:first_other])
    assert [spec.action for spec in rest[first_other:]] == sorted(
        (spec.action for spec in rest[first_other:]), key=ACTIONS.index
    )


def test_whole_space_is_distinct_and_complete() -> None:
    candidates = enumerate_candidates(failed=None, entities=ENTITIES)
    assert len(set(candidates)) == len(candidates)
    expected = sum(len(argument_tuples(a, ENTITIES)) for a in ACTIONS) * Grid().size
    assert len(candidates) == expected
    assert all(len(c.arguments) == ACTION_ARITY[c.action] for c in candidates)


@pytest.mark.parametrize("action", ACTIONS)
def test_enumeration_is_deterministic(action: str) -> None:
    args = argument_tuples(action, ENTITIES)[0]
    failed = TrialSpec(action, args, ControllerParams(0.4, 0.15, "top"))
    assert enumerate_candidates(failed=failed, entities=ENTITIES) == enumerate_candidates(
        failed=failed, entities=dict(reversed(list(ENTITIES.items())))
    )


def test_the_candidate_space_size_is_counted_from_the_scenes() -> None:
    from llcps.cps.candidates import candidate_space_size
    from llcps.scenarios import SCENARIOS

    for name in SCENARIOS:  # two objects and a container: push 3, push_together 3*2, remove 2, place 2
        assert candidate_space_size(name) == (3 + 6 + 2 + 2) * Grid().size - 1
    assert candidate_space_size() == max(candidate_space_size(name) for name in SCENARIOS)
