"""Trials already simulated, reused: physics is a function of (scene, saved state, call).

A world restored from a serialized state is the same in any process
(:meth:`~llcps.sim.world.World.restore_serialized`), so a trial started from the same
saved state with the same controller call gives the same result bit for bit. An
experiment grid asks that question again and again: every sequence of a seed starts
scenario 1 from the same failure state, and exploration orders overlap. A
:class:`TrialMemo` answers a repeated question from the first simulation of it —
the trial's result and the physics state it ended in — instead of stepping the
engine again. What an agent records is unchanged; only the engine time is saved
(a reused trial keeps the wall seconds of its first simulation).
"""

from __future__ import annotations

import hashlib
import json
from collections import OrderedDict
from dataclasses import asdict, dataclass
from typing import Any, Mapping

from llcps.domain import TrialSpec
from llcps.sim.trial import TrialResult

#: Entries kept before the least recently used is dropped (a state is ~40 kB).
DEFAULT_CAPACITY = 20_000


def memo_key(scene: Mapping[str, Any], state: bytes, spec: TrialSpec, max_steps: int) -> bytes:
    """Digest of everything a trial's physics depends on."""
    h = hashlib.sha256()
    h.update(json.dumps(scene, sort_keys=True).encode())
    h.update(b"\0")
    h.update(state)
    h.update(b"\0")
    h.update(json.dumps({"spec": asdict(spec), "max_steps": max_steps}, sort_keys=True).encode())
    return h.digest()


@dataclass
class MemoStats:
    hits: int = 0
    misses: int = 0


class TrialMemo:
    """An in-memory, least-recently-used map from :func:`memo_key` to (result, end state)."""

    def __init__(self, capacity: int = DEFAULT_CAPACITY) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        self.capacity = capacity
        self.stats = MemoStats()
        self._entries: OrderedDict[bytes, tuple[TrialResult, bytes]] = OrderedDict()

    def __len__(self) -> int:
        return len(self._entries)

    def get(self, key: bytes) -> tuple[TrialResult, bytes] | None:
        entry = self._entries.get(key)
        if entry is None:
            self.stats.misses += 1
            return None
        self._entries.move_to_end(key)
        self.stats.hits += 1
        return entry

    def put(self, key: bytes, result: TrialResult, end_state: bytes) -> None:
        self._entries[key] = (result, end_state)
        self._entries.move_to_end(key)
        while len(self._entries) > self.capacity:
            self._entries.popitem(last=False)
