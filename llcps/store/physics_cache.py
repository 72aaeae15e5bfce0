"""The persistent physics cache: simulated trials, kept in the experience store.

An entry maps :func:`llcps.sim.cache.trial_key` (a digest of the physics settings,
the scene, the start state, the controller call and the step cap) to the trial's
result and the physics state it ended in. Every worker of an experiment run opens
the same store, so a trial one worker simulated is answered for the others, and
for every later run on the store. It is a cache, not experience: no branch refers
to it, and pruning it only means later runs compute some physics again.

Everything read back is untrusted: an entry's size is capped and its content hash
checked before anything is decoded, the result is decoded field by field, and the
end state must pass :func:`validate_state` (a bounded inflate, once per digest and
cache handle) and the restoring world's structure check
(:meth:`llcps.sim.world.World.check_serialized`, memoized per process) before a
world restores it. An entry that fails is ignored as a miss and replaced by the
next simulation of its key.

Seals: the structure check and the probe cost about 0.1 s for each end state a
process has not seen before, and a resumed run sees every one for the first time.
So an entry carries a seal: an HMAC-SHA256 of its key and content hash under a
secret that never enters the store, a key file in the user's data directory
(:func:`default_key_file`; ``LLCPS_CACHE_KEY`` names another). Only a process holding the
secret can seal, and it seals only end states it saved from a world of the key's
scene, or that passed the checks. An entry with a valid seal is restored without
the checks (``trust``); one without (written before seals, on another machine, or
altered in the store) goes through them and is sealed once it passes. Without a
usable key file nothing is sealed and every entry is checked as before.

Size: each entry is about 40 kB (the compressed end state dominates). The cache is
bounded by :data:`DEFAULT_MAX_BYTES` unless a store setting says otherwise; an
experiment run prunes it back to the bound when it ends, least recently used
first, and ``llcps cache prune`` does so on demand.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import os
import secrets
import tempfile
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, Callable

import platformdirs
from sqlalchemy import String, delete, func, insert, or_, select, type_coerce, update
from sqlalchemy.exc import IntegrityError, SQLAlchemyError

from llcps.errors import LlcpsError, StoreError
from llcps.sim import snapshot as snapshots
from llcps.sim.cache import MAX_RESULT_BYTES, CachedTrial, StateCheck, StateTrust, decode_result, encode_result
from llcps.sim.result import TrialResult
from llcps.store import backends
from llcps.store.tables import PhysicsCacheEntry
from llcps.store.transactions import utc_now

#: Default bound of the cache's size (result and end-state bytes), 2 GiB: about 50,000 trials.
DEFAULT_MAX_BYTES = 2 << 30
#: Store setting that overrides :data:`DEFAULT_MAX_BYTES` (bytes, as text).
MAX_BYTES_SETTING = "physics_cache_max_bytes"
#: Largest compressed end state accepted (a scene's state is ~40 kB).
MAX_STATE_BYTES = snapshots.MAX_COMPRESSED_STATE_BYTES
#: Largest end state once decompressed (a scene's state is ~90 kB).
MAX_RAW_STATE_BYTES = snapshots.MAX_STATE_BYTES
#: Environment variable naming the file of the seal secret (default: :func:`default_key_file`).
KEY_FILE_ENV = "LLCPS_CACHE_KEY"
#: Bytes of a seal secret.
SECRET_BYTES = 32
#: Hits remembered before their use is written back (``last_used``, ``hits``).
_FLUSH_EVERY = 64

StateValidator = Callable[[bytes], None]
"""Raises ValueError when bytes are not a physics state a world may restore."""


def validate_state(state: bytes) -> None:
    """Check that ``state`` is a bounded serialized physics state.

    A state is a zlib stream of a ``.bullet`` file (or the raw file). The stream
    is inflated under the cap of :func:`llcps.sim.snapshot.decompress_state`, so a
    crafted entry cannot exhaust memory, and must hold a Bullet file header. Its
    structure is checked against the scene by the world that restores it
    (:meth:`llcps.sim.world.World.check_serialized`, passed to
    :meth:`StorePhysicsCache.get` as ``check``).

    Raises:
        ValueError: it is not one.
    """
    if not isinstance(state, (bytes, bytearray)) or not state:
        raise ValueError("an end state is non-empty bytes")
    try:
        raw = snapshots.decompress_state(bytes(state))
    except LlcpsError as exc:
        raise ValueError(exc.message) from None
    if not raw.startswith(b"BULLET"):
        raise ValueError("not a Bullet physics state")


def content_hash(result: bytes, end_state: bytes) -> str:
    """sha256 of an entry's result, a NUL and its end state."""
    digest = hashlib.sha256(result)
    digest.update(b"\x00")
    digest.update(end_state)
    return digest.hexdigest()


def default_key_file() -> Path:
    """Where this user's seal secret is kept: ``$LLCPS_CACHE_KEY``, else a file in the user data directory."""
    named = os.environ.get(KEY_FILE_ENV)
    return Path(named).expanduser() if named else platformdirs.user_data_path("llcps") / "physics-cache.key"


@functools.lru_cache(maxsize=8)
def load_secret(path: Path) -> bytes | None:
    """The seal secret in ``path``, made (random, mode 0600) if the file is missing; None if unusable.

    Processes starting together agree: the file appears whole (a hard link of a
    finished temporary file), and a process that finds one made first reads it.
    """
    try:
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=".physics-cache-key-")  # mode 0600
            try:
                os.write(fd, secrets.token_bytes(SECRET_BYTES))
                os.close(fd)
                try:
                    os.link(temporary, path)
                except FileExistsError:
                    pass  # another process made it first: use theirs
            finally:
                os.unlink(temporary)
        with open(path, "rb") as fh:
            secret = fh.read(4 * SECRET_BYTES)
    except OSError:
        return None
    return secret if len(secret) >= SECRET_BYTES else None


def seal(secret: bytes, key: str, sha: str) -> str:
    """The seal of the entry ``key`` whose content hash is ``sha``."""
    return hmac.new(secret, f"{key}\x00{sha}".encode(), hashlib.sha256).hexdigest()


def _sealed(value: Any, expected: str) -> bool:
    """Whether a stored seal (untrusted: any type) is ``expected``."""
    return isinstance(value, str) and value.isascii() and hmac.compare_digest(value, expected)


@dataclass
class CacheCounts:
    """What one process asked of the cache."""

    hits: int = 0
    misses: int = 0
    rejected: int = 0
    stored: int = 0

    @property
    def hit_rate(self) -> float | None:
        asked = self.hits + self.misses
        return None if asked == 0 else self.hits / asked

    def as_json(self) -> dict[str, Any]:
        return {"hits": self.hits, "misses": self.misses, "rejected": self.rejected, "stored": self.stored, "hit_rate": self.hit_rate}


class StorePhysicsCache:
    """The physics cache of one store, as :class:`llcps.sim.cache.PhysicsCache`.

    Safe to use from several processes at once (each with its own instance):
    entries are written in short transactions of their own, and a key written by
    two processes keeps the first.

    Args:
        engine: the store's SQLAlchemy engine (``Store.engine``).
        validator: the end-state check (default :func:`validate_state`).
        key_file: the seal secret's file (default :func:`default_key_file`).
    """

    def __init__(self, engine: Any, *, validator: StateValidator = validate_state, key_file: Path | None = None) -> None:
        self._engine = engine
        self._validator = validator
        self._secret = load_secret(key_file if key_file is not None else default_key_file())
        self.counts = CacheCounts()
        self._used: dict[str, int] = {}
        self._seals: dict[str, str] = {}
        self._rejected: set[str] = set()
        #: Digests of end states that passed ``validator`` already.
        self._validated: set[str] = set()

    def get(self, key: str, *, check: StateCheck | None = None, trust: StateTrust | None = None) -> CachedTrial | None:
        """The entry under ``key``, or None when absent or when it fails validation.

        Args:
            key: a :func:`llcps.sim.cache.trial_key`.
            check: also run on the end state of an entry without a valid seal (the
                restoring world's structure check); an entry it refuses is a miss,
                replaced by the next :meth:`put`, and one it passes is sealed.
            trust: run instead of ``check`` on the end state of a sealed entry (the
                restoring world's :meth:`~llcps.sim.world.World.trust_serialized`).
        """
        try:
            with self._engine.connect() as conn:
                row = conn.execute(
                    select(
                        PhysicsCacheEntry.result,
                        PhysicsCacheEntry.end_state,
                        PhysicsCacheEntry.sha256,
                        func.length(PhysicsCacheEntry.result),
                        func.length(PhysicsCacheEntry.end_state),
                        func.substr(PhysicsCacheEntry.seal, 1, 64),
                    ).where(PhysicsCacheEntry.key == key)
                ).first()
        except SQLAlchemyError as exc:
            raise StoreError(f"cannot read the physics cache: {str(getattr(exc, 'orig', exc)).splitlines()[0]}",
                             hint="run with --no-cache, or check `llcps db status`") from exc  # fmt: skip
        if row is None:
            self.counts.misses += 1
            return None
        entry = self._check(key, row, check, trust)
        if entry is None:
            self.counts.misses += 1
            self.counts.rejected += 1
            self._rejected.add(key)
            return None
        self.counts.hits += 1
        self._used[key] = self._used.get(key, 0) + 1
        if len(self._used) >= _FLUSH_EVERY:
            self.flush()
        return entry

    def _check(self, key: str, row: Any, check: StateCheck | None, trust: StateTrust | None) -> CachedTrial | None:
        result, state, sha, result_size, state_size, stored_seal = row
        if result_size is None or state_size is None or result_size > MAX_RESULT_BYTES or state_size > MAX_STATE_BYTES:
            return None
        result, state = bytes(result), bytes(state)
        if content_hash(result, state) != sha:
            return None
        try:
            decoded = decode_result(result)
            if sha not in self._validated:
                self._validator(state)
                self._validated.add(sha)
            expected = None if self._secret is None else seal(self._secret, key, sha)
            if expected is not None and _sealed(stored_seal, expected):
                if trust is not None:
                    trust(state)
            elif check is not None:
                check(state)
                if expected is not None:
                    self._seals[key] = expected  # written with the next flush
        except (ValueError, LlcpsError):
            return None
        return CachedTrial(result=decoded, end_state=state)

    def put(self, key: str, result: TrialResult, end_state: bytes) -> None:
        """Keep a simulated trial; an entry already there (from another process) is kept."""
        encoded = encode_result(result)
        now = utc_now()
        sha = content_hash(encoded, end_state)
        values = {
            "key": key,
            "result": encoded,
            "end_state": bytes(end_state),
            "sha256": sha,
            "seal": None if self._secret is None else seal(self._secret, key, sha),
            "size": len(encoded) + len(end_state),
            "hits": 0,
            "created_at": now,
            "last_used": now,
        }
        try:
            with self._engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                with conn.begin():
                    if key in self._rejected:  # replace the entry that failed validation
                        conn.execute(delete(PhysicsCacheEntry).where(PhysicsCacheEntry.key == key))
                    conn.execute(insert(PhysicsCacheEntry).values(**values))
        except IntegrityError:
            return  # another process stored the same key first; its physics is the same
        except SQLAlchemyError as exc:
            raise StoreError(f"cannot write the physics cache: {str(getattr(exc, 'orig', exc)).splitlines()[0]}",
                             hint="run with --no-cache, or check `llcps db status`") from exc  # fmt: skip
        self._rejected.discard(key)
        self.counts.stored += 1

    def flush(self) -> None:
        """Write back when entries were last used (least recently used go first when pruning),
        and the seals of entries that passed the checks."""
        if not self._used and not self._seals:
            return
        used, self._used = self._used, {}
        seals, self._seals = self._seals, {}
        now = utc_now()
        try:
            with self._engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                with conn.begin():
                    for key, n in used.items():
                        conn.execute(
                            update(PhysicsCacheEntry)
                            .where(PhysicsCacheEntry.key == key)
                            .values(last_used=now, hits=PhysicsCacheEntry.hits + n)
                        )
                    for key, value in seals.items():
                        conn.execute(update(PhysicsCacheEntry).where(PhysicsCacheEntry.key == key).values(seal=value))
        except SQLAlchemyError:
            pass  # bookkeeping only: a busy store must not fail a trial


# ------------------------------------------------------------------------ size, pruning
@dataclass(frozen=True)
class CacheStatus:
    """Size of a store's physics cache."""

    entries: int
    bytes: int
    hits: int
    max_bytes: int
    oldest_use: str | None
    newest_use: str | None
    #: Entries carrying a seal (of any secret; whether this user's verifies is known on reading).
    sealed: int = 0

    def as_json(self) -> dict[str, Any]:
        return {
            "entries": self.entries,
            "sealed": self.sealed,
            "bytes": self.bytes,
            "hits": self.hits,
            "max_bytes": self.max_bytes,
            "oldest_use": self.oldest_use,
            "newest_use": self.newest_use,
        }


@dataclass(frozen=True)
class PruneResult:
    """What :func:`prune` removed and kept."""

    removed: int
    removed_bytes: int
    kept: int
    kept_bytes: int
    dry_run: bool

    def as_json(self) -> dict[str, Any]:
        return {
            "removed": self.removed,
            "removed_bytes": self.removed_bytes,
            "kept": self.kept,
            "kept_bytes": self.kept_bytes,
            "dry_run": self.dry_run,
        }


def _write(store: Any):  # noqa: ANN202 - a connection context
    return store._write()


#: Largest size an entry can have: its result and its compressed end state at their caps.
MAX_ENTRY_BYTES = MAX_RESULT_BYTES + MAX_STATE_BYTES

#: Largest bound the cache setting may hold (1 PiB).
MAX_LIMIT_BYTES = 2**50

_CACHE_CHANGED_HINT = "the row was changed outside llcps; `llcps cache prune --to 0` empties the cache (it holds no experience)"


def max_bytes(store: Any) -> int:
    """The store's bound on the cache size (its setting, else :data:`DEFAULT_MAX_BYTES`).

    Raises:
        StoreError: the setting is not a whole number of bytes from 0 to :data:`MAX_LIMIT_BYTES`.
    """
    with store._read() as conn:
        value = store._get_setting(conn, MAX_BYTES_SETTING)
    if value is None:
        return DEFAULT_MAX_BYTES
    text = value.strip() if isinstance(value, str) else ""
    if not text.isascii() or not text.isdigit() or len(text) > 16 or int(text) > MAX_LIMIT_BYTES:
        raise StoreError(
            f"the store's physics cache bound (setting {MAX_BYTES_SETTING}) is {str(value)[:40]!r}, not a number of bytes",
            hint="set it again with `llcps cache limit 2GB`",
        )
    return int(text)


def set_max_bytes(store: Any, limit: int) -> None:
    """Make ``limit`` the store's bound on the cache size."""
    if not 0 <= limit <= MAX_LIMIT_BYTES:
        raise LlcpsError(f"a cache size must be from 0 to 1 PiB ({limit})", hint="pass a size such as 500MB or 2GB")
    with _write(store) as conn:
        store._set_setting(conn, MAX_BYTES_SETTING, str(int(limit)))


def status(store: Any) -> CacheStatus:
    """How many entries and bytes the cache holds.

    Raises:
        StoreError: an entry's size, hits or time of use is not what llcps writes.
    """
    used = type_coerce(PhysicsCacheEntry.last_used, String)  # checked below, not parsed by the driver
    with store._read() as conn:
        bad = conn.execute(
            select(PhysicsCacheEntry.key).where(
                or_(
                    PhysicsCacheEntry.size.is_(None),
                    PhysicsCacheEntry.size < 0,
                    PhysicsCacheEntry.size > MAX_ENTRY_BYTES,
                    PhysicsCacheEntry.hits < 0,
                )
            ).limit(1)
        ).first()
        n, sealed, size, hits, oldest, newest = conn.execute(
            select(
                func.count(),
                func.count(PhysicsCacheEntry.seal),
                func.coalesce(func.sum(PhysicsCacheEntry.size), 0),
                func.coalesce(func.sum(PhysicsCacheEntry.hits), 0),
                func.min(used),
                func.max(used),
            )
        ).one()
    if bad is not None:
        raise StoreError(f"physics cache entry {str(bad[0])[:16]!r} is malformed: its size or hits are out of range", hint=_CACHE_CHANGED_HINT)
    oldest, newest = (_use_time(value) for value in (oldest, newest))
    return CacheStatus(
        entries=int(n),
        sealed=int(sealed),
        bytes=int(size),
        hits=int(hits),
        max_bytes=max_bytes(store),
        oldest_use=oldest,
        newest_use=newest,
    )


def _use_time(value: Any) -> str | None:
    """A stored ``last_used`` as ISO text, checked (SQLite keeps it as text; PostgreSQL as a timestamp)."""
    if value is None:
        return None
    text = value.isoformat(sep=" ") if isinstance(value, datetime) else str(value)[:64]
    try:
        datetime.fromisoformat(text)
    except ValueError:
        raise StoreError(f"the physics cache holds a time of use that is not a time ({text[:32]!r})", hint=_CACHE_CHANGED_HINT) from None
    return text


def prune(store: Any, *, limit: int | None = None, dry_run: bool = False) -> PruneResult:
    """Remove the least recently used entries until the cache holds at most ``limit`` bytes.

    Args:
        store: the experience store.
        limit: bytes to keep at most (None: the store's bound, :func:`max_bytes`; 0 empties it).
        dry_run: only say what would be removed.
    """
    keep = max_bytes(store) if limit is None else int(limit)
    if keep < 0:
        raise LlcpsError(f"a cache size cannot be negative ({keep})", hint="pass a size such as 500MB or 2GB")
    with store._read() as conn:
        rows = conn.execute(
            select(PhysicsCacheEntry.key, PhysicsCacheEntry.size).order_by(
                PhysicsCacheEntry.last_used.desc(), PhysicsCacheEntry.key
            )
        ).all()
    kept_bytes, kept, doomed, doomed_bytes = 0, 0, [], 0
    for key, size in rows:
        if not isinstance(size, int) or not 0 <= size <= MAX_ENTRY_BYTES:  # a changed row: it goes, counted as nothing
            doomed.append(key)
            continue
        if kept_bytes + size <= keep and not doomed:
            kept_bytes += size
            kept += 1
        else:
            doomed.append(key)
            doomed_bytes += size
    if doomed and not dry_run:
        with _write(store) as conn:
            for start in range(0, len(doomed), 500):
                conn.execute(delete(PhysicsCacheEntry).where(PhysicsCacheEntry.key.in_(doomed[start : start + 500])))
    return PruneResult(removed=len(doomed), removed_bytes=doomed_bytes, kept=kept, kept_bytes=kept_bytes, dry_run=dry_run)


__all__ = [
    "DEFAULT_MAX_BYTES",
    "CacheCounts",
    "CacheStatus",
    "PruneResult",
    "StorePhysicsCache",
    "content_hash",
    "max_bytes",
    "prune",
    "set_max_bytes",
    "status",
    "validate_state",
]
