"""SQLAlchemy 2.0 typed tables of the experience store.

These classes describe the head schema; the Alembic revisions in ``migrations/``
create it step by step, and ``tests/test_migrations.py`` checks that both agree.
ORM rows never leave :mod:`llcps.store`: the store returns frozen dataclasses.

Trial and branch ids use SQLite's AUTOINCREMENT (PostgreSQL sequences behave the
same way): an id is never reused, so "trial id <= fork point" keeps meaning the
same thing after trials are deleted.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    SmallInteger,
    String,
    Text,
    false,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

#: Alembic's bookkeeping table; its name marks a database as an llcps store.
VERSION_TABLE = "llcps_alembic_version"

#: SQLite ``PRAGMA application_id`` of llcps stores ("LLCP" in ASCII). It lives in
#: the file header, so a file can be recognised without opening it as a database.
SQLITE_APPLICATION_ID = 0x4C4C4350

#: Longest branch name accepted.
MAX_BRANCH_NAME = 100

NAMING_CONVENTION = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}


class Branch(Base):
    """A line of experience: a parent and the trial id it forked at."""

    __tablename__ = "branches"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(MAX_BRANCH_NAME), unique=True)
    parent_id: Mapped[int | None] = mapped_column(ForeignKey("branches.id"))
    fork_point: Mapped[int] = mapped_column(BigInteger, default=0)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class Setting(Base):
    """Small key/value facts about the store, e.g. the current branch."""

    __tablename__ = "settings"

    key: Mapped[str] = mapped_column(String(64), primary_key=True)
    value: Mapped[str] = mapped_column(Text)


class Run(Base):
    """One CLI invocation or experiment sequence (provenance of its trials)."""

    __tablename__ = "runs"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    command: Mapped[str] = mapped_column(Text)
    seed: Mapped[int | None] = mapped_column(BigInteger)
    config: Mapped[dict[str, Any]]
    # A name, not a foreign key: the run log outlives deleted branches.
    branch: Mapped[str] = mapped_column(String(MAX_BRANCH_NAME))
    llcps_version: Mapped[str] = mapped_column(String(32))
    status: Mapped[str] = mapped_column(String(32))
    started_at: Mapped[datetime] = mapped_column(DateTime)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime)
    # Provenance (llcps.provenance); NULL for runs stored before it was kept.
    git_commit: Mapped[str | None] = mapped_column(String(64))
    git_dirty: Mapped[bool | None] = mapped_column(Boolean)
    python_version: Mapped[str | None] = mapped_column(String(32))
    pybullet_version: Mapped[str | None] = mapped_column(String(32))
    torch_version: Mapped[str | None] = mapped_column(String(32))
    sklearn_version: Mapped[str | None] = mapped_column(String(32))
    numpy_version: Mapped[str | None] = mapped_column(String(32))
    host: Mapped[str | None] = mapped_column(String(255))
    cpu_count: Mapped[int | None] = mapped_column(Integer)
    # The live-writer marker (llcps.store.writers): the process writing a running run and
    # when it last said it was alive; NULL for runs stored before revision 0009.
    pid: Mapped[int | None] = mapped_column(Integer)
    heartbeat_at: Mapped[datetime | None] = mapped_column(DateTime)


class Episode(Base):
    """One scenario solve within a run."""

    __tablename__ = "episodes"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"))
    branch_id: Mapped[int] = mapped_column(ForeignKey("branches.id"), index=True)
    scenario: Mapped[str] = mapped_column(String(64))
    condition: Mapped[str] = mapped_column(String(32))
    model: Mapped[str | None] = mapped_column(String(64))
    measure: Mapped[str | None] = mapped_column(String(64))
    seed: Mapped[int | None] = mapped_column(BigInteger)
    status: Mapped[str] = mapped_column(String(32))
    summary: Mapped[dict[str, Any]]
    started_at: Mapped[datetime] = mapped_column(DateTime)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime)


class Snapshot(Base):
    """A physics state a trial started from, stored once per content hash."""

    __tablename__ = "snapshots"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    sha256: Mapped[str] = mapped_column(String(64), unique=True)
    scene: Mapped[dict[str, Any]]
    state: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class Trial(Base):
    """One executed action: the unit of the lifelong training set."""

    __tablename__ = "trials"
    __table_args__ = (
        Index("ix_trials_branch_id_id", "branch_id", "id"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    branch_id: Mapped[int] = mapped_column(ForeignKey("branches.id"))
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"))
    episode_id: Mapped[int | None] = mapped_column(ForeignKey("episodes.id"))
    source: Mapped[str] = mapped_column(String(16))
    scenario: Mapped[str | None] = mapped_column(String(64))
    action: Mapped[str] = mapped_column(String(32))
    arguments: Mapped[list[Any]]
    rate: Mapped[float] = mapped_column(Float)
    movement_magnitude: Mapped[float] = mapped_column(Float)
    orientation: Mapped[str] = mapped_column(String(16))
    # Table-1 features of the arguments, packed (llcps.store.trials.pack_features):
    # one value per trial, so loading a training set neither decodes JSON nor
    # fetches fourteen columns per row.
    features: Mapped[bytes] = mapped_column(LargeBinary)
    positive_visibility: Mapped[int] = mapped_column(SmallInteger)
    negative_visibility: Mapped[int] = mapped_column(SmallInteger)
    positive_reachability: Mapped[int] = mapped_column(SmallInteger)
    negative_reachability: Mapped[int] = mapped_column(SmallInteger)
    positive_touching: Mapped[int] = mapped_column(SmallInteger)
    negative_touching: Mapped[int] = mapped_column(SmallInteger)
    solved: Mapped[bool] = mapped_column(Boolean)
    sim_steps: Mapped[int] = mapped_column(Integer)
    wall_seconds: Mapped[float] = mapped_column(Float)
    # Answered from the physics cache: wall_seconds is then this run's lookup, and
    # simulation_wall_seconds the wall time of the simulation that computed it.
    cache_hit: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    simulation_wall_seconds: Mapped[float | None] = mapped_column(Float)
    seed: Mapped[int] = mapped_column(BigInteger)
    snapshot_id: Mapped[int | None] = mapped_column(ForeignKey("snapshots.id"))
    created_at: Mapped[datetime] = mapped_column(DateTime)
    extra: Mapped[dict[str, Any]]


class TrialChangeRow(Base):
    """A trial's symbolic change (atoms added and deleted) and the scene it happened in.

    Kept beside the trial, keyed by its id, so that the trials table and its hot
    decoder stay as they are; written in the same transaction as the trial. A row with
    source ``unknown`` marks a trial of an older store whose change could not be
    recovered by replay (no stored start state, or a replay that did not match).
    """

    __tablename__ = "trial_changes"

    trial_id: Mapped[int] = mapped_column(ForeignKey("trials.id", ondelete="CASCADE"), primary_key=True)
    source: Mapped[str] = mapped_column(String(16))
    # The states, packed (llcps.store.trial_changes.pack_atoms), and the scene's bodies (pack_bodies).
    before: Mapped[bytes] = mapped_column(LargeBinary)
    added: Mapped[bytes] = mapped_column(LargeBinary)
    deleted: Mapped[bytes] = mapped_column(LargeBinary)
    bodies: Mapped[bytes] = mapped_column(LargeBinary)


class TrialExamplesRow(Base):
    """A trial's encoded goal examples (llcps.models.relational.pack_examples), kept once.

    Derived data: encoded the first time a fit reads the trial, tagged with the model
    code that encoded them; a row of other code is encoded again and replaced.
    """

    __tablename__ = "trial_examples"

    trial_id: Mapped[int] = mapped_column(ForeignKey("trials.id", ondelete="CASCADE"), primary_key=True)
    code: Mapped[str] = mapped_column(String(16))
    data: Mapped[bytes] = mapped_column(LargeBinary)


class TrialBlockRow(Base):
    """:data:`~llcps.store.trial_blocks.BLOCK` consecutive trials of one branch, packed as
    columns (llcps.store.trial_blocks.pack), so that a branch's visible set is read as a
    few hundred rows rather than a million.

    Derived data: written in the transaction that stores the trial completing the block,
    deleted with any trial it holds, and not used where it no longer matches its rows.
    """

    __tablename__ = "trial_blocks"
    __table_args__ = (Index("ix_trial_blocks_branch_id_first_id", "branch_id", "first_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    branch_id: Mapped[int] = mapped_column(ForeignKey("branches.id", ondelete="CASCADE"))
    first_id: Mapped[int] = mapped_column(Integer)
    last_id: Mapped[int] = mapped_column(Integer)
    trials: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary)


class Operator(Base):
    """A learned operator (the knowledge-base expansion K')."""

    __tablename__ = "operators"
    __table_args__ = (
        Index("ix_operators_branch_id_id", "branch_id", "id"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    branch_id: Mapped[int] = mapped_column(ForeignKey("branches.id"))
    name: Mapped[str] = mapped_column(String(200))
    pddl: Mapped[str] = mapped_column(Text)
    definition: Mapped[dict[str, Any]]
    scenario: Mapped[str | None] = mapped_column(String(64))
    episode_id: Mapped[int | None] = mapped_column(ForeignKey("episodes.id"))
    watermark: Mapped[int] = mapped_column(BigInteger)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class OperatorExecution(Base):
    """One execution of an operator of K or K' as a plan step, whether it worked, and its
    context: the facts over the step's arguments before it ran, lifted to the operator's
    variables (a JSON list of atoms, each a list of strings).

    The counts of these rows set an operator's plan cost on a branch (operators costed
    by experience); like operators they carry the watermark of the branch when written,
    so a branch forked earlier does not see later executions.
    """

    __tablename__ = "operator_executions"
    __table_args__ = (
        Index("ix_operator_executions_branch_id_id", "branch_id", "id"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    branch_id: Mapped[int] = mapped_column(ForeignKey("branches.id"))
    operator: Mapped[str] = mapped_column(String(200))
    success: Mapped[bool] = mapped_column(Boolean)
    context: Mapped[list[Any]]
    episode_id: Mapped[int | None] = mapped_column(ForeignKey("episodes.id"))
    trial_id: Mapped[int | None] = mapped_column(ForeignKey("trials.id"))
    watermark: Mapped[int] = mapped_column(BigInteger)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class WorldModel(Base):
    """A fitted world model as bytes in a format that cannot run code when loaded."""

    __tablename__ = "world_models"
    __table_args__ = (
        Index("ix_world_models_branch_id_name_seed", "branch_id", "name", "seed"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    branch_id: Mapped[int] = mapped_column(ForeignKey("branches.id"))
    name: Mapped[str] = mapped_column(String(64))
    seed: Mapped[int] = mapped_column(BigInteger)
    watermark: Mapped[int] = mapped_column(BigInteger)
    artifact: Mapped[bytes] = mapped_column(LargeBinary)
    sha256: Mapped[str] = mapped_column(String(64))
    meta: Mapped[dict[str, Any]]
    created_at: Mapped[datetime] = mapped_column(DateTime)


class PhysicsCacheEntry(Base):
    """A simulated trial's result and end state, keyed by everything its physics depends on.

    See :mod:`llcps.store.physics_cache`. Not experience: pruning it changes no
    branch, only how much physics later runs must compute again.
    """

    __tablename__ = "physics_cache"
    __table_args__ = (Index("ix_physics_cache_last_used", "last_used"),)

    key: Mapped[str] = mapped_column(String(64), primary_key=True)
    result: Mapped[bytes] = mapped_column(LargeBinary)
    end_state: Mapped[bytes] = mapped_column(LargeBinary)
    # sha256 of result, a NUL and end_state: checked before either is decoded.
    sha256: Mapped[str] = mapped_column(String(64))
    # HMAC of key and sha256 under a secret outside the store: this machine made or checked the entry.
    seal: Mapped[str | None] = mapped_column(String(64), nullable=True)
    size: Mapped[int] = mapped_column(Integer)
    hits: Mapped[int] = mapped_column(Integer, default=0)
    created_at: Mapped[datetime] = mapped_column(DateTime)
    last_used: Mapped[datetime] = mapped_column(DateTime)
