"""W per branch: fitted world models, stored as bytes of a safe format (npz, a torch
state_dict, JSON) with the watermark of the data they were fitted on.

A model is seen by its branch and by branches forked from it later; a refit on the
same data finds the model fitted on the most of it (see
:meth:`ModelArtifactQueries.latest_world_model`).
"""

from __future__ import annotations

import hashlib
from typing import Any, Mapping

from sqlalchemy import func, insert, select

from llcps.errors import LlcpsError, StoreError
from llcps.store import visibility
from llcps.store.branches import BranchQueries
from llcps.store.records import ModelArtifact
from llcps.store.tables import WorldModel
from llcps.store.transactions import CHANGED_HINT, utc_now
from llcps.store.trials import iso_timestamp


#: The name a trained exploration policy (``llcps rl train``) is stored under, beside the
#: world models of a branch; unlike theirs, its row is no cache of a fit.
POLICY_NAME = "rl-policy"

#: Largest world model artifact stored or read back (bytes); a larger row is refused
#: unread, as a physics state larger than :data:`llcps.store.snapshots.MAX_SNAPSHOT_BYTES` is.
MAX_MODEL_BYTES = 64 * 2**20


class ModelArtifactQueries(BranchQueries):
    """Saving a fitted world model on a branch and finding the one to reuse."""

    def save_world_model(
        self, *, branch: str, name: str, seed: int, watermark: int, artifact: bytes, meta: Mapping[str, Any]
    ) -> int:
        """Store a fitted world model's bytes (a safe format: npz, state_dict, JSON).

        Args:
            watermark: :meth:`max_visible_trial_id` of ``branch`` when the fit started.
        """
        if not isinstance(artifact, (bytes, bytearray, memoryview)):
            raise LlcpsError("a world model artifact must be bytes", hint="serialise it as npz, a torch state_dict or JSON")
        data = bytes(artifact)
        if len(data) > MAX_MODEL_BYTES:
            raise LlcpsError(f"a world model artifact of {len(data):,} bytes is larger than the {MAX_MODEL_BYTES:,} a store keeps",
                             hint="fit a smaller model")
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(WorldModel).values(
                    branch_id=chain[0].branch_id,
                    name=name,
                    seed=int(seed),
                    watermark=int(watermark),
                    artifact=data,
                    sha256=hashlib.sha256(data).hexdigest(),
                    meta=dict(meta),
                    created_at=utc_now(),
                )
            ).inserted_primary_key[0]

    def latest_world_model(self, branch: str | None, name: str, seed: int) -> ModelArtifact | None:
        """The visible model of that name and seed fitted on the most data (then the newest)."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            names = {link.branch_id: link.name for link in chain}
            found = conn.execute(
                select(WorldModel.id, func.length(WorldModel.artifact))
                .where(visibility.clause(chain, WorldModel.branch_id, WorldModel.watermark), WorldModel.name == name, WorldModel.seed == seed)
                .order_by(WorldModel.watermark.desc(), WorldModel.id.desc())
                .limit(1)
            ).first()
            if found is None:
                return None
            model_id, size = found
            # The size first, without the bytes: an oversized row is never read into memory.
            if not isinstance(size, int) or not 0 <= size <= MAX_MODEL_BYTES:
                raise StoreError(f"stored world model {model_id} holds {size} bytes, more than the {MAX_MODEL_BYTES:,} a world model may", hint=CHANGED_HINT)
            row = conn.execute(select(WorldModel).where(WorldModel.id == model_id)).first()
        if row is None:
            return None
        if not isinstance(row.artifact, (bytes, bytearray, memoryview)) or not isinstance(row.meta, dict):
            raise StoreError(f"stored world model {row.id} is malformed: its artifact is not bytes or its meta not an object", hint=CHANGED_HINT)
        return ModelArtifact(
            id=row.id,
            branch=names[row.branch_id],
            name=row.name,
            seed=row.seed,
            watermark=row.watermark,
            artifact=bytes(row.artifact),
            sha256=row.sha256,
            meta=row.meta,
            created_at=iso_timestamp(row.created_at) or "",
        )
