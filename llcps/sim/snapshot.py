"""Checking a serialized physics state before the physics engine reads it.

A stored snapshot is untrusted input: the engine's ``restoreState`` follows the
pointers and counts inside a ``.bullet`` file without checking them, so a few
flipped bytes crash the process. A state passes three gates before it reaches
the engine (see docs/reliability.md):

1. **Size.** :func:`decompress_state` inflates at most :data:`MAX_STATE_BYTES`;
   a decompression bomb is refused after that many bytes, not after it filled memory.
2. **Structure** (:func:`llcps.sim.state_check.check_state`, pure Python, a few
   milliseconds): the file is compared with the state of the same scene freshly built.
3. **Probe** (:func:`probe`, run by :func:`llcps.sim.world.probe_states`). What the
   structure check cannot rule out is restored first in a child process; a crash, a
   hang or runaway memory there becomes a clean :class:`~llcps.errors.LlcpsError` here.

A state that passed, or that this process serialized itself, is remembered by
digest (:class:`TrustedStates`), so restoring it again costs one SHA-256.
"""

from __future__ import annotations

import faulthandler
import hashlib
import json
import os
import select
import signal
import time
import zlib
from collections import OrderedDict
from typing import Any, Callable, Mapping

from llcps.errors import LlcpsError

#: Largest decompressed physics state accepted (a three-entity scene is ~90 kB).
MAX_STATE_BYTES = 8 * 2**20
#: Largest compressed physics state accepted (what a snapshot row may hold).
MAX_COMPRESSED_STATE_BYTES = 8 * 2**20
#: How long a probe may take before it counts as a hang (seconds).
PROBE_TIMEOUT = 120.0
#: Address-space cap of a probe process (bytes): runaway allocation fails there.
PROBE_MEMORY = 4 * 2**30
#: Digests remembered per process.
TRUSTED_CAPACITY = 65_536

_HINT = "the snapshot was changed outside llcps; replay another trial, or restore the database from a copy"
#: How every raw ``.bullet`` file begins.
BULLET_HEADER = b"BULLET"


class StateError(LlcpsError):
    """A serialized physics state that may not reach the engine."""

    def __init__(self, message: str, hint: str = _HINT) -> None:
        super().__init__(message, hint=hint)


def decompress_state(data: bytes, *, limit: int = MAX_STATE_BYTES) -> bytes:
    """The raw ``.bullet`` bytes of a stored state, inflating at most ``limit`` bytes.

    Raw ``.bullet`` bytes pass through (after the same size check).
    """
    if len(data) > MAX_COMPRESSED_STATE_BYTES:
        raise StateError(f"the physics state is {len(data):,} bytes, more than the {MAX_COMPRESSED_STATE_BYTES:,} allowed")
    if data.startswith(BULLET_HEADER):
        if len(data) > limit:
            raise StateError(f"the physics state is {len(data):,} bytes, more than the {limit:,} allowed")
        return bytes(data)
    inflater = zlib.decompressobj()
    try:
        raw = inflater.decompress(data, limit + 1)
    except zlib.error as exc:
        raise StateError(f"not a physics state: {exc}", hint="states come from World.serialize_state()") from exc
    if len(raw) > limit or inflater.unconsumed_tail:
        raise StateError(f"the physics state inflates to more than {limit:,} bytes")
    if not inflater.eof:
        raise StateError("not a physics state: the compressed data is truncated", hint="states come from World.serialize_state()")
    return raw


def state_digest(raw: bytes) -> str:
    """SHA-256 of raw state bytes (what :class:`TrustedStates` remembers)."""
    return hashlib.sha256(raw).hexdigest()


# --------------------------------------------------------------------------- trust and the probe


class TrustedStates:
    """Digests of states known to restore safely in a scene, remembered per process (bounded)."""

    def __init__(self, capacity: int = TRUSTED_CAPACITY) -> None:
        self._keys: OrderedDict[tuple[str, str], None] = OrderedDict()
        self._capacity = capacity

    def __contains__(self, key: tuple[str, str]) -> bool:
        return key in self._keys

    def add(self, key: tuple[str, str]) -> None:
        self._keys[key] = None
        if len(self._keys) > self._capacity:
            self._keys.popitem(last=False)

    def clear(self) -> None:
        self._keys.clear()


#: This process's trusted states: (scene key, state digest).
TRUSTED = TrustedStates()


def scene_key(scene: Mapping[str, Any]) -> str:
    """A digest of a scene description (canonical JSON)."""
    return hashlib.sha256(json.dumps(scene, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _limit_memory(extra: int) -> None:  # pragma: no cover - runs in the probe process
    """Cap the address space at what the process already maps plus ``extra`` bytes."""
    try:
        import resource

        with open("/proc/self/statm") as fh:
            mapped = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        resource.setrlimit(resource.RLIMIT_AS, (mapped + extra, resource.RLIM_INFINITY))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    except (OSError, ValueError, ImportError):
        pass


def probe(work: Callable[[], str], *, timeout: float = PROBE_TIMEOUT) -> None:
    """Run ``work`` in a child process, where a crash, a hang or runaway memory is harmless.

    The child is a fork of this process (it starts in milliseconds with the engine
    already loaded). ``work`` returns "" when every state it restored is sound, or why
    one is not (:func:`llcps.sim.world.probe_states` restores states into a world there).

    Raises:
        StateError: the child crashed, hung, ran out of memory or refused a state.
    """
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child reports through the pipe and its exit status
        code = 3
        try:
            os.close(read_end)
            faulthandler.disable()  # a crash here is the expected outcome, not a report for the parent's log
            quiet = os.open(os.devnull, os.O_WRONLY)  # the engine prints its complaints
            os.dup2(quiet, 1)
            os.dup2(quiet, 2)
            _limit_memory(PROBE_MEMORY)
            message = work()
            os.write(write_end, message.encode()[:4000])
            code = 0 if not message else 2
        except BaseException:  # noqa: BLE001 - whatever happens, leave through os._exit
            pass
        finally:
            os._exit(code)
    os.close(write_end)
    try:
        status, detail = _wait(pid, read_end, timeout)
    except BaseException:
        _kill(pid)
        raise
    finally:
        os.close(read_end)
    if os.WIFSIGNALED(status):
        try:
            name = signal.Signals(os.WTERMSIG(status)).name
        except ValueError:
            name = f"signal {os.WTERMSIG(status)}"
        raise StateError(f"the physics engine crashed on the physics state ({name})")
    code = os.WEXITSTATUS(status)
    if code == 2:
        raise StateError(f"the physics state cannot be restored: {detail}")
    if code != 0:
        raise StateError(f"checking the physics state failed (exit code {code}; out of memory?)")


def _wait(pid: int, read_end: int, timeout: float) -> tuple[int, str]:
    """The child's exit status and message, waiting at most ``timeout`` seconds in all.

    The pipe tells when the child is done: it turns readable with the message, and at
    end of file once the child has exited (crashed or not), so the wait ends the
    moment the child does, with no polling interval to overshoot.
    """
    deadline = time.monotonic() + timeout
    chunks: list[bytes] = []
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0 or not select.select([read_end], [], [], remaining)[0]:
            _kill(pid)
            raise StateError(f"restoring the physics state did not finish within {timeout:g} s")
        data = os.read(read_end, 4096)
        if not data:
            break
        chunks.append(data)
    while True:  # the child has closed its end: it is exiting, or a moment away from it
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status, b"".join(chunks).decode(errors="replace")
        if time.monotonic() > deadline:
            _kill(pid)
            raise StateError(f"restoring the physics state did not finish within {timeout:g} s")
        time.sleep(0.0005)


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass
