"""The experience store: the lifelong training set, on git-like branches.

In the paper's terms, a branch holds one line of lifelong learning:

* its trials, the lifelong training set the world models are fitted on, each with the
  symbolic change it made (:mod:`llcps.store.training_set`);
* K', the operators it learned, and how operators fared when they ran
  (:mod:`llcps.store.operator_log`);
* W, the fitted world models, as artifacts stamped with the data they saw
  (:mod:`llcps.store.model_artifacts`).

A branch also sees what its parent saw up to its fork point
(:mod:`llcps.store.visibility`, :mod:`llcps.store.branches`). Open a store with
:meth:`Store.open`; see docs/store.md for the user guide. Importing this package does
not import the CLI (typer, rich) or Alembic.
"""

from __future__ import annotations

from llcps.store.records import (
    BranchChange,
    BranchInfo,
    CompactResult,
    EpisodeRecord,
    ExecutionCounts,
    ExecutionRecord,
    ModelArtifact,
    OperatorRecord,
    RunRecord,
    SnapshotRecord,
    StoreStatus,
)
from llcps.store.branches import MAIN_BRANCH, PRETRAIN, RESET_TARGETS, validate_branch_name
from llcps.store.store import Store
from llcps.store.transactions import utc_now

__all__ = [
    "MAIN_BRANCH",
    "PRETRAIN",
    "RESET_TARGETS",
    "BranchChange",
    "BranchInfo",
    "CompactResult",
    "EpisodeRecord",
    "ExecutionCounts",
    "ExecutionRecord",
    "ModelArtifact",
    "OperatorRecord",
    "RunRecord",
    "SnapshotRecord",
    "Store",
    "StoreStatus",
    "utc_now",
    "validate_branch_name",
]
