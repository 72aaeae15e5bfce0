"""Packed features, atoms and bodies: every entity, state and body round-trips bit for bit, and
bytes without the layout are refused (the refusals of stored changes: tests/test_trial_changes.py)."""

from __future__ import annotations

import copy
import pickle
import struct
from dataclasses import replace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from llcps.domain import BODY_KINDS, SHAPES, EntityFeatures
from llcps.trial_records import Body
from llcps.errors import LlcpsError
from llcps.store.trial_changes import pack_atoms, pack_bodies, unpack_atoms, unpack_bodies
from llcps.store.trials import pack_features, unpack_features

names = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x1f"), min_size=1, max_size=12)
numbers = st.floats(allow_nan=False, allow_infinity=False)
entities = st.builds(EntityFeatures, shape=names, volume=numbers, color=names, vector_magnitude=numbers, unit_x=numbers, unit_y=numbers, unit_z=numbers)


@given(st.lists(entities, min_size=0, max_size=2))
def test_features_round_trip(features: list[EntityFeatures]) -> None:
    assert unpack_features(pack_features(features)) == tuple(features)


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"\x01",
        b"\x02\x01" + bytes(40) + b"box\x1fred",  # an unknown layout
        b"\x01\x03" + bytes(120),  # more arguments than any action takes
        b"\x01\x01" + bytes(20),  # numbers cut short
        b"\x01\x01" + bytes(40) + b"box",  # a colour missing
        b"\x01\x01" + bytes(40) + b"\x1fred",  # an empty shape
        b"\x01\x01" + struct.pack("<5d", 1, 2, 3, 4, 5) + b"\xff\xfe\x1fred",  # not UTF-8
    ],
)
def test_bytes_without_the_layout_are_refused(data: bytes) -> None:
    with pytest.raises(LlcpsError, match="malformed"):
        unpack_features(data)


def test_names_with_the_separator_cannot_be_packed() -> None:
    with pytest.raises(LlcpsError):
        pack_features([EntityFeatures("bo\x1fx", 1.0, "red", 1.0, 0.0, 0.0, 1.0)])


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
@pytest.mark.parametrize("where", range(5))
def test_a_non_finite_number_is_refused(bad: float, where: int) -> None:
    numbers = [0.001, 0.2, 1.0, 0.0, 0.0]
    numbers[where] = bad
    with pytest.raises(LlcpsError, match="not a finite number"):
        unpack_features(b"\x01\x01" + struct.pack("<5d", *numbers) + b"box\x1fred")


@pytest.mark.parametrize(("shape", "color"), [("cube", "red"), ("box", "purple")])
def test_table1_refuses_names_outside_its_categories(shape: str, color: str) -> None:
    data = pack_features([EntityFeatures("box", 1.0, "red", 1.0, 0.0, 0.0, 1.0), EntityFeatures(shape, 1.0, color, 1.0, 0.0, 0.0, 1.0)])
    assert unpack_features(data)[1].shape == shape  # the layout alone allows any name
    with pytest.raises(LlcpsError, match="unknown shape or color"):
        unpack_features(data, table1=True)


finite = st.floats(allow_nan=False, allow_infinity=False)
vectors = st.tuples(finite, finite, finite)
bodies = st.builds(
    Body,
    name=names,
    kind=st.sampled_from(BODY_KINDS),
    shape=st.one_of(st.none(), st.sampled_from(SHAPES)),
    lo=vectors,
    hi=vectors,
    centre=vectors,
)


@given(st.lists(bodies, max_size=12))
def test_bodies_round_trip(scene: list[Body]) -> None:
    unpacked = unpack_bodies(pack_bodies(scene))
    assert unpacked == tuple(scene)
    assert all(type(v) is tuple for b in unpacked for v in (b.lo, b.hi, b.centre))


def test_a_body_name_with_the_separator_cannot_be_packed() -> None:
    with pytest.raises(LlcpsError):
        pack_bodies([Body("cu\x1fbe", "object", "box", (0, 0, 0), (1, 1, 1), (0.5, 0.5, 0.5))])


atom_names = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x1e\x1f"), min_size=1, max_size=12)
atoms = st.lists(atom_names, min_size=1, max_size=3).map(tuple)


@given(st.frozensets(atoms, max_size=30))
def test_states_round_trip(state: frozenset[tuple[str, ...]]) -> None:
    known: dict[str, tuple[str, ...]] = {}
    assert unpack_atoms(pack_atoms(state), known) == state
    assert unpack_atoms(pack_atoms(state), known) == state  # again, from what it remembered
    assert pack_atoms(state) == pack_atoms(set(state))  # one spelling whatever the order


@pytest.mark.parametrize("atom", [(), ("a", "b", "c", "d"), ("in", ""), ("in", "a\x1eb")])
def test_an_atom_that_cannot_be_stored_is_refused(atom: tuple[str, ...]) -> None:
    with pytest.raises(LlcpsError):
        pack_atoms([atom])


# -- records read from a store hold their features packed until first use ------------------------


def _read_back(tmp_path, new_trial, n: int = 6) -> tuple[list, list]:  # noqa: ANN001
    from llcps.store import Store

    made = [new_trial(seed) for seed in range(n)]
    with Store.open(str(tmp_path / "llcps.db"), create=True) as store:
        store.add_trials(made)
        read = store.visible_trials("main")
    return made, read


def test_a_read_record_builds_its_features_once_on_first_use(tmp_path, new_trial) -> None:  # noqa: ANN001
    made, read = _read_back(tmp_path, new_trial)
    assert all(m.stored_features is None for m in made)
    for m, r in zip(made, read):
        assert "features" not in r.__dict__ and r.stored_features is not None
        assert r.features == m.features and r.features is r.features  # built once, then an attribute
        assert r == replace(m, id=r.id, created_at=r.created_at)


def test_a_read_record_pickles_copies_and_replaces_like_a_made_one(tmp_path, new_trial) -> None:  # noqa: ANN001
    made, read = _read_back(tmp_path, new_trial, 2)
    for r in read:
        assert pickle.loads(pickle.dumps(r)) == r and copy.deepcopy(r) == r
        assert replace(r, seed=99).features == r.features
        with pytest.raises(AttributeError, match="no attribute 'neither'"):
            r.neither  # noqa: B018


def test_the_models_read_the_same_rows_and_digest_from_read_and_made_records(tmp_path, new_trial) -> None:  # noqa: ANN001
    import numpy as np

    from llcps.models.features import encode_inputs
    from llcps.models.persistence import training_digest

    made, read = _read_back(tmp_path, new_trial)
    made = [replace(m, id=r.id) for m, r in zip(made, read)]
    assert np.array_equal(encode_inputs(read), encode_inputs(made), equal_nan=True)
    assert training_digest(read, {}) == training_digest(made, {})
    assert not any("features" in r.__dict__ for r in read)  # neither built a record's EntityFeatures
    first = made[0].features[0]
    nudged = [replace(made[0], features=(replace(first, volume=first.volume * (1 + 1e-12)),) + made[0].features[1:]), *made[1:]]
    assert training_digest(nudged, {}) != training_digest(made, {})


def test_flat_rows_of_read_and_made_records_agree_without_building_features(tmp_path, new_trial) -> None:  # noqa: ANN001
    from llcps.store.flat import base_values

    made, read = _read_back(tmp_path, new_trial)
    made = [replace(m, id=r.id, created_at=r.created_at) for m, r in zip(made, read)]
    rows = [base_values(r) for r in read]
    assert rows == [base_values(m) for m in made]
    assert not any("features" in r.__dict__ for r in read)
    assert rows[0]["arg0_volume"] == made[0].features[0].volume and rows[0]["arg0_shape"] == made[0].features[0].shape
    assert [r.features[0].as_dict() for r in read] == [{k: getattr(m.features[0], k) for k in r.features[0].__dataclass_fields__} for m, r in zip(made, read)]
