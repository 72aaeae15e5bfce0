"""World models stored on their branch: fit once per training set, reuse until newer trials arrive.

A stored model carries its *watermark*, the largest trial id its branch could see
when it was fitted. A branch's visible trials only grow (new trials get larger ids),
so a stored model whose watermark equals the branch's current one was fitted on
exactly today's training set and is loaded instead of refitted, if the same model
code fitted it: a stored model also carries :func:`model_code`, a digest of the
source of :mod:`llcps.models`, and one fitted by other code (an older release, a
changed encoder or learner) is refitted and replaced, so that what a model predicts
never depends on when its store was made. Artifacts load without executing anything
(see :mod:`llcps.models.artifact`); one that fails to load is refitted and replaced, with
a warning.

A stored model that is behind is fitted again on the whole training set, except a
scheduled model whose bins still hold (:mod:`llcps.models.schedule`): it is brought up
by adding the counts of the trials after its watermark, which reads those trials only,
and gives the model a fit from nothing would.

A fit of the goal-aware head reads every visible trial's encoded (candidate, atom)
examples; they are encoded once, the first time a fit reads the trial, and kept in
the store beside it (:func:`keep_examples`, :func:`stored_examples`), tagged with
:func:`model_code`: a later fit, on this branch or on a fork, reads them instead of
encoding the trial again. The bytes are checked as they are read, and examples that
fail the check are encoded again; either way the fit sees the same numbers.

Within one process, fits are also remembered by the content of their training set
(:func:`training_digest`): a process that solves many episodes on copies of the
same trials in different stores (an experiment worker runs every measure and both
conditions of a seed from the same pretraining set) fits each model once and copies
it after. A fit is deterministic for its seed and training set, so the copy is the
model a fit would give, and it is stored on the branch all the same.
The digest reads every trial, so it is taken only when a remembered fit has as
many trials, ending with the same one.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import logging
import struct
import time
from dataclasses import asdict, dataclass
from importlib import resources
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

from llcps.domain import check_seed
from llcps.trial_records import StoredFeatures, TrialChange, TrialRecord
from llcps.training import TrainingChanges, TrainingSet
from llcps.errors import LlcpsError, StoreError
from llcps.models.base import WorldModel
from llcps.models.registry import WorldModelEntry, world_model_entry
from llcps.models.relational import Examples, pack_examples, unpack_examples
from llcps.models.schedule import bins_trials
from llcps.store.trial_changes import pack_atoms, pack_bodies

if TYPE_CHECKING:
    from llcps.store import Store
    from llcps.store.records import ModelArtifact

logger = logging.getLogger(__name__)

#: How many fitted models this process remembers (:func:`_fit`), the least recently used dropped first.
FIT_MEMO_SIZE = 8
#: Between a trial's entity names in its digest (a control character, in no name).
_SEPARATOR = "\x1f"


@functools.cache
def model_code() -> str:
    """A digest of the source of every module of :mod:`llcps.models` (what a fit runs).

    Any change to that source makes stored models stale, comments included: a refit
    costs a fit, while a stale model would make predictions depend on the store's history.
    """
    digest = hashlib.sha256()
    for module in sorted(resources.files("llcps.models").iterdir(), key=lambda f: f.name):
        if module.name.endswith(".py"):
            digest.update(module.name.encode() + b"\0" + module.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def training_digest(records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> str:
    """A digest of everything a fit reads from its training set, in order.

    That is each trial's id, seed, spec, features and outcome, and its known change
    (the state before, the atoms added and deleted, the scene's bodies, in the form the
    store keeps them: :mod:`llcps.store.trial_changes`); provenance
    (branch, run, timestamps, wall seconds) is left out, since no model reads it.
    """
    digest = hashlib.blake2b(digest_size=20)
    texts: dict[int, str] = {}  # by id() of a spec or outcome: the records share them, and keep them alive
    packs: dict[int, bytes] = {}  # by id() of a change's state or bodies, in their stored form: shared alike
    for r in records:
        spec, outcome = r.spec, r.outcome
        spec_text = texts.get(id(spec))
        if spec_text is None:
            p = spec.params
            spec_text = texts[id(spec)] = f"{spec.action}|{spec.arguments}|{p.rate!r}|{p.movement_magnitude!r}|{p.orientation}"
        outcome_text = texts.get(id(outcome))
        if outcome_text is None:
            outcome_text = texts[id(outcome)] = str(outcome.bits())
        stored = r.stored_features or StoredFeatures.of(r.features)  # the same bytes for a trial read or made
        digest.update(f"{r.id}|{r.seed}|{spec_text}|{outcome_text}|{len(stored)}|".encode())
        digest.update(struct.pack(f"<{len(stored.numbers)}d", *stored.numbers))
        digest.update(_SEPARATOR.join(stored.names).encode())
        change = changes.get(r.id) if r.id is not None else None
        if change is None:
            digest.update(b"|-\n")
            continue
        for part, pack in ((change.before, pack_atoms), (change.added, pack_atoms), (change.deleted, pack_atoms), (change.bodies, pack_bodies)):
            packed = packs.get(id(part))
            if packed is None:
                packed = packs[id(part)] = pack(part)
            digest.update(len(packed).to_bytes(4, "little") + packed)
        digest.update(b"\n")
    return digest.hexdigest()


def _fit(
    entry: WorldModelEntry,
    seed: int,
    records: Sequence[TrialRecord],
    changes: Mapping[int, TrialChange],
    goal: bool,
    examples: Callable[[], Mapping[int, Examples]] | None = None,
) -> WorldModel:
    """A fresh fit, or a copy of this process's fit of the same training set.

    Args:
        examples: gives goal examples encoded before, by trial id (read only when a fit runs).
    """
    shape = (entry.name, seed, goal, len(records), records[-1].id if records else None)
    same_shape = [r for r in _FITS if r.shape == shape]
    digest = None
    if same_shape:  # only a fit of as many trials, ending with the same one, can match
        digest = training_digest(records, changes)
        for remembered in same_shape:
            if remembered.key() == digest:
                _FITS.remove(remembered)
                _FITS.append(remembered)
                return copy.deepcopy(remembered.model)
    model = entry(seed)
    if goal and examples is not None:
        model.goal.table.prime(examples())
    model.fit(records, changes, goal=goal)
    # the caller updates its own model during exploration, so the memo keeps a copy
    _FITS.append(_Remembered(shape, copy.deepcopy(model), digest, records, changes))
    del _FITS[:-FIT_MEMO_SIZE]
    return model


class _Remembered:
    """A fit this process remembers, keyed by its training set's digest, computed only when
    another training set of the same shape asks (a digest reads every trial)."""

    def __init__(
        self, shape: tuple[object, ...], model: WorldModel, digest: str | None, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]
    ) -> None:
        #: (model, seed, goal, trials, last trial id): what a training set must share to be compared.
        self.shape = shape
        self.model = model
        self._digest = digest
        # copies of the containers (not of the frozen records): a caller may go on adding to its own
        self._training = None if digest else (tuple(records), dict(changes))

    def key(self) -> str:
        if self._digest is None:
            assert self._training is not None
            self._digest = training_digest(*self._training)
            self._training = None
        return self._digest


#: The fits this process remembers (:func:`_fit`), least recently used first.
_FITS: list[_Remembered] = []


def stored_examples(store: Store, branch: str) -> dict[int, Examples]:
    """The goal examples kept in the store for the trials ``branch`` sees, encoded by
    today's model code; a row that does not read back is left out (encoded again)."""
    found = {}
    for trial_id, data in store.visible_examples(branch, model_code()).items():
        try:
            found[trial_id] = unpack_examples(data, trial_id)
        except LlcpsError as exc:
            logger.warning("stored goal examples of trial %s are unusable, encoding them again: %s", trial_id, exc.message)
    return found


def keep_examples(store: Store, model: WorldModel) -> None:
    """Keep in the store the goal examples ``model`` encoded (so no later fit encodes them again)."""
    table = model.goal.table
    if table.encoded:
        store.save_examples(model_code(), {trial_id: pack_examples(e) for trial_id, e in table.encoded.items() if trial_id > 0})
        table.encoded = {}


def clear_fits() -> None:
    """Forget the fits this process remembers."""
    _FITS.clear()


def fit_or_load(
    store: Store,
    branch: str,
    name: str,
    seed: int,
    *,
    records: Sequence[TrialRecord] | None = None,
    changes: Mapping[int, TrialChange] | None = None,
    goal: bool = True,
) -> WorldModel:
    """The world model ``name`` fitted on every trial ``branch`` sees.

    Args:
        store: the experience store.
        branch: the branch whose trials train the model and which owns the artifact.
        name: a WORLD_MODELS name.
        seed: the model's seed (part of the stored model's identity).
        records: the branch's visible trials, if the caller already loaded them
            (reloaded from the store when they do not reach its watermark).
        changes: their known symbolic changes, if the caller already loaded them. A
            training set and its changes taken at the branch's watermark
            (``Store.training_set``) also give their counts, so they are not counted again.
        goal: the model must have its goal-aware head (False for a measure that
            ranks by Omega alone: the head is then neither fitted nor stored).

    Returns:
        The stored model when it is current (fitted on today's trials and on as many
        known changes as the branch has: a backfill makes it stale; by today's model
        code, :func:`model_code`) and has the goal head if asked for, else a fresh fit
        (which is stored).

    Raises:
        UnknownNameError: ``name`` is not a registered world model.
    """
    entry = world_model_entry(name)
    check_seed(seed, "model seed")
    watermark = store.max_visible_trial_id(branch)
    trials: int | None = None
    if isinstance(records, TrainingSet) and isinstance(changes, TrainingChanges) and records.watermark == watermark:
        trials, known = records.base, changes.base  # a set taken at this watermark has counted them
    else:
        known = store.count_visible_changes(branch)
    try:
        stored = store.latest_world_model(branch, name, seed)
    except StoreError as exc:  # a damaged row: the model is derived data, so fit it again
        logger.warning("stored world model %s is unusable, refitting: %s", name, exc.message)
        stored = None
    if (
        stored is not None
        and stored.watermark == watermark
        and stored.meta.get("changes", known) == known
        and stored.meta.get("code") == model_code()
        and (stored.meta.get("goal", True) is True or not goal)
    ):
        try:
            return entry.load(stored.artifact, stored.meta, seed)
        except LlcpsError as exc:
            logger.warning("stored world model %s (id %s) is unusable, refitting: %s", name, stored.id, exc)
    elif stored is not None and stored.meta.get("code") == model_code() and (stored.meta.get("goal", True) is True or not goal):
        model = _extended(store, branch, entry, stored, seed, watermark, known, trials)
        if model is not None:
            _save(store, branch, model, watermark, known)
            return model
    if records is None or max((r.id for r in records), default=0) != watermark:
        records = store.visible_trials(branch)
        if records and records[-1].id > watermark:  # another writer's trials since: the model is of its watermark
            records = [r for r in records if r.id <= watermark]
    if changes is None or len(changes) != known:
        changes = store.visible_changes(branch)
        changes = {i: change for i, change in changes.items() if i <= watermark}
    model = _fit(entry, seed, records, changes, goal, lambda: stored_examples(store, branch))
    _save(store, branch, model, watermark, known)
    return model


def _extended(
    store: Store,
    branch: str,
    entry: WorldModelEntry,
    stored: ModelArtifact,
    seed: int,
    watermark: int,
    known: int,
    trials: int | None = None,
) -> WorldModel | None:
    """The stored model of a scheduled world model brought up to the trials ``branch``
    sees up to ``watermark`` by counting the ones after its own (:meth:`WorldModel.extend`),
    or None when a fit is needed: the model does not count, the grown set fits bins of
    its own (:mod:`llcps.models.schedule`), the trials and changes up to its watermark
    are no longer those it learned (deleted, or a backfill added changes), or trials
    arrived past ``watermark`` while reading (another writer).

    Args:
        trials: how many trials the branch sees up to ``watermark``, if the caller
            counted them (else counted here).
    """
    if not entry.model_class().scheduled:
        return None
    if trials is None:
        trials = store.count_visible_trials(branch)
    if not bins_trials(trials) == stored.meta.get("bins_trials") or not isinstance(stored.meta.get("changes"), int):
        return None
    try:
        model = entry.load(stored.artifact, stored.meta, seed)
    except LlcpsError as exc:
        logger.warning("stored world model %s (id %s) is unusable, refitting: %s", entry.name, stored.id, exc)
        return None
    records = store.visible_trials(branch, after_id=stored.watermark)
    changes = store.visible_changes(branch, after_id=stored.watermark)
    if (
        model.n_trials + len(records) != trials
        or stored.meta["changes"] + len(changes) != known
        or (records and records[-1].id != watermark)
        or any(trial_id > watermark for trial_id in changes)
        or not model.can_extend(trials)
    ):
        return None
    return model.extend(records, changes)


def _save(store: Store, branch: str, model: WorldModel, watermark: int, known: int) -> None:
    """Store a fitted model on ``branch`` with its watermark, and the goal examples it encoded."""
    keep_examples(store, model)
    artifact, meta = model.to_artifact()
    meta["changes"] = known
    meta["code"] = model_code()
    store.save_world_model(branch=branch, name=model.name, seed=model.seed, watermark=watermark, artifact=artifact, meta=meta)


@dataclass(frozen=True)
class FittedModel:
    """One world model fitted (or found current) on a branch."""

    name: str
    seed: int
    trials: int
    fit_seconds: float

    def as_json(self) -> dict[str, object]:
        return asdict(self)


def fit_models(
    store: Store,
    branch: str,
    names: Sequence[str],
    seed: int,
    *,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[FittedModel]:
    """Fit (and store) each named world model on every trial ``branch`` sees.

    Args:
        progress: called as ``progress(name, done, total)`` before each fit and once at the end.
    """
    records = store.visible_trials(branch)
    changes = store.visible_changes(branch)
    fitted = []
    for index, name in enumerate(names):
        if progress is not None:
            progress(name, index, len(names))
        started = time.perf_counter()
        fit_or_load(store, branch, name, seed, records=records, changes=changes)
        fitted.append(FittedModel(name, seed, len(records), time.perf_counter() - started))
    if progress is not None:
        progress("done", len(names), len(names))
    return fitted
