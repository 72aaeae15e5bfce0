"""Snapshots: physics states a trial starts from, stored once by content.

A snapshot is a scene (JSON) and the simulator's serialized state (bytes), keyed by
the hash of both, so trials that start from the same state share one row. What is
read back is checked for its size and against its hash before it is used.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Mapping

from sqlalchemy import func, insert, select
from sqlalchemy.exc import IntegrityError, SQLAlchemyError

from llcps.domain import check_id
from llcps.errors import LlcpsError, StoreError
from llcps.store import backends
from llcps.store.records import SnapshotRecord
from llcps.store.tables import Snapshot
from llcps.store.transactions import CHANGED_HINT, Transactions, db_error, utc_now


#: Largest stored physics state read back (bytes, compressed); larger rows are refused unread.
MAX_SNAPSHOT_BYTES = 8 * 2**20


class SnapshotQueries(Transactions):
    """Storing physics states once and reading them back checked."""

    @staticmethod
    def snapshot_hash(scene: Mapping[str, Any], state: bytes) -> str:
        """Content hash of a snapshot: canonical scene JSON, a NUL, the state bytes."""
        digest = hashlib.sha256(json.dumps(scene, sort_keys=True, separators=(",", ":")).encode())
        digest.update(b"\x00")
        digest.update(state)
        return digest.hexdigest()

    def put_snapshot(self, *, scene: Mapping[str, Any], state: bytes) -> int:
        """Store a physics state once; the same scene and bytes give the same id."""
        sha = self.snapshot_hash(scene, state)
        found = self._snapshot_id(sha)
        if found is not None:
            return found
        try:
            with self._engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                with conn.begin():
                    return conn.execute(
                        insert(Snapshot).values(sha256=sha, scene=dict(scene), state=bytes(state), created_at=utc_now())
                    ).inserted_primary_key[0]
        except IntegrityError:  # another writer stored the same content first
            found = self._snapshot_id(sha)
            if found is None:
                raise
            return found
        except SQLAlchemyError as exc:
            raise db_error(exc, self._url) from exc

    def _snapshot_id(self, sha: str) -> int | None:
        with self._read() as conn:
            return conn.scalar(select(Snapshot.id).where(Snapshot.sha256 == sha))

    def get_snapshot(self, snapshot_id: int) -> SnapshotRecord:
        """A stored physics state by id, after checking its size and its content hash.

        Raises:
            StoreError: the row is larger than :data:`MAX_SNAPSHOT_BYTES`, its scene is
                not a JSON object, or scene and state no longer match the stored hash.
        """
        check_id(snapshot_id, "snapshot id")
        with self._read() as conn:
            size = conn.execute(select(func.length(Snapshot.state)).where(Snapshot.id == snapshot_id)).first()
            if size is None:
                raise LlcpsError(f"unknown snapshot {snapshot_id}", hint="snapshot ids come from a trial's snapshot_id")
            if size[0] is None or size[0] > MAX_SNAPSHOT_BYTES:
                raise StoreError(f"snapshot {snapshot_id} holds {size[0]} bytes, more than the {MAX_SNAPSHOT_BYTES:,} a physics state may", hint=CHANGED_HINT)
            row = conn.execute(select(Snapshot.id, Snapshot.scene, Snapshot.state, Snapshot.sha256).where(Snapshot.id == snapshot_id)).first()
        if row is None:
            raise LlcpsError(f"unknown snapshot {snapshot_id}", hint="snapshot ids come from a trial's snapshot_id")
        if not isinstance(row.scene, dict) or not isinstance(row.state, (bytes, bytearray, memoryview)):
            raise StoreError(f"snapshot {snapshot_id} is malformed: its scene is not a JSON object", hint=CHANGED_HINT)
        state = bytes(row.state)
        if not isinstance(row.sha256, str) or self.snapshot_hash(row.scene, state) != row.sha256:
            raise StoreError(f"snapshot {snapshot_id} does not match its content hash: it was changed after it was stored", hint=CHANGED_HINT)
        return SnapshotRecord(id=row.id, scene=row.scene, state=state, sha256=row.sha256)
