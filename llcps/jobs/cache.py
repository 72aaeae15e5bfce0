"""``llcps cache``: the store's physics cache — its size and bound, and pruning it."""

from __future__ import annotations

from typing import TYPE_CHECKING

from llcps.jobs._common import StoreRef, opened

if TYPE_CHECKING:
    from llcps.store.physics_cache import CacheStatus, PruneResult


def cache_status(*, store: StoreRef) -> CacheStatus:
    """Entries, bytes and the size bound of the physics cache."""
    from llcps.store import physics_cache

    with opened(store) as s:
        return physics_cache.status(s)


def prune_cache(*, store: StoreRef, limit: int | None = None, dry_run: bool = False) -> PruneResult:
    """Remove the least recently used entries until the cache holds at most ``limit`` bytes
    (None: the store's bound); with ``dry_run``, only say what would go."""
    from llcps.store import physics_cache

    with opened(store) as s:
        return physics_cache.prune(s, limit=limit, dry_run=dry_run)


def limit_cache(*, store: StoreRef, max_bytes: int) -> CacheStatus:
    """Set the size bound the cache is pruned to (kept in the store); returns the new status."""
    from llcps.store import physics_cache

    with opened(store) as s:
        physics_cache.set_max_bytes(s, max_bytes)
        return physics_cache.status(s)
