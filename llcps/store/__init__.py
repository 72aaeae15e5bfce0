"""The experience store: the lifelong training set, on git-like branches.

Open it with :meth:`Store.open`; see docs/store.md for the user guide.
Importing this package does not import the CLI (typer, rich) or Alembic.
"""

from __future__ import annotations

from llcps.store.records import (
    BranchChange,
    BranchInfo,
    CompactResult,
    EpisodeRecord,
    ExecutionCounts,
    ModelArtifact,
    OperatorRecord,
    RunRecord,
    SnapshotRecord,
    StoreStatus,
)
from llcps.store.store import MAIN_BRANCH, PRETRAIN, RESET_TARGETS, Store, validate_branch_name

__all__ = [
    "MAIN_BRANCH",
    "PRETRAIN",
    "RESET_TARGETS",
    "BranchChange",
    "BranchInfo",
    "CompactResult",
    "EpisodeRecord",
    "ExecutionCounts",
    "ModelArtifact",
    "OperatorRecord",
    "RunRecord",
    "SnapshotRecord",
    "Store",
    "StoreStatus",
    "validate_branch_name",
]
