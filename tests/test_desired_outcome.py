from __future__ import annotations

import numpy as np

from llcps.cps.outcomes import desired_outcome
from llcps.domain import OUTCOME_NAMES


def test_missing_in_asks_for_a_new_contact() -> None:
    w = desired_outcome(missing_add=[("in", "cube", "bucket")], missing_del=[("on", "cube", "table")])
    assert w[OUTCOME_NAMES.index("positive_touching")] == 0.5
    assert w[OUTCOME_NAMES.index("negative_touching")] == 0.5
    assert np.isclose(w.sum(), 1.0)


def test_nothing_known_is_uniform() -> None:
    w = desired_outcome(missing_add=[("mystery", "x")], missing_del=[])
    assert np.allclose(w, 1 / 6)
