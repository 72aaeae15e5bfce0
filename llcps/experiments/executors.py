"""Executors of experiment tasks: a local process pool, or Ray (the run's ``--engine``).

Both offer the same operations to the scheduler: submit a task, wait for some to
finish, collect one's result, tell which running sequences have finished their
first scenario (the local pool only), and close (stopping the tasks in flight when
aborting). The task function is :func:`llcps.experiments.worker.execute_task`.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor
from concurrent.futures import wait as wait_futures
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Iterable, Protocol

from llcps.errors import LlcpsError, UnknownNameError
from llcps.experiments.tasks import Task, TaskOutput
from llcps.experiments.worker import FIRST_SCENARIO, PID, THREAD_VARIABLES, execute_task, init_local_worker

#: ``--engine`` choices: a local process pool, or Ray (``pip install 'llcps[ray]'``).
ENGINES: tuple[str, ...] = ("local", "ray")


class EngineError(LlcpsError):
    """The engine itself failed (a worker process died), not one task."""


class Engine(Protocol):
    """What the scheduler needs of an engine."""

    name: str
    workers: int

    def submit(self, task: Task) -> Any: ...

    def wait(self, handles: Iterable[Any], timeout: float) -> list[Any]: ...

    def result(self, handle: Any) -> TaskOutput: ...

    def past_first_scenario(self) -> set[str]:
        """Labels of sequence tasks known to have finished their first scenario."""
        ...

    def close(self, *, abort: bool, pending: Iterable[Any] = ()) -> None: ...


class LocalEngine:
    """A spawn-context process pool; each worker owns its own PyBullet client.

    Every worker reports its process id when it starts (through a queue), so an
    abort can stop the workers in flight without reaching into the pool, and each
    sequence task the end of its first scenario.
    """

    name = "local"

    def __init__(self, workers: int) -> None:
        context = multiprocessing.get_context("spawn")
        self.workers = workers
        self._events = context.SimpleQueue()
        self._known: set[int] = set()
        self._first_done: set[str] = set()
        self._pool = ProcessPoolExecutor(
            max_workers=workers, mp_context=context, initializer=init_local_worker, initargs=(self._events,)
        )

    def submit(self, task: Task) -> Future:
        return self._pool.submit(execute_task, task)

    def wait(self, handles: Iterable[Future], timeout: float) -> list[Future]:
        done, _ = wait_futures(list(handles), timeout=timeout, return_when=FIRST_COMPLETED)
        return list(done)

    def result(self, handle: Future) -> TaskOutput:
        try:
            return handle.result()
        except BrokenProcessPool:
            raise EngineError(
                "a worker process died (out of memory, or killed)",
                hint="every task imported so far is kept; run the same command again to resume",
            ) from None

    def _drain(self) -> None:
        while not self._events.empty():
            kind, value = self._events.get()
            if kind == PID:
                self._known.add(value)
            elif kind == FIRST_SCENARIO:
                self._first_done.add(value)

    def worker_pids(self) -> list[int]:
        """Process ids of the workers started so far."""
        self._drain()
        return sorted(self._known)

    def past_first_scenario(self) -> set[str]:
        self._drain()
        return set(self._first_done)

    def close(self, *, abort: bool, pending: Iterable[Future] = ()) -> None:
        if abort:  # drop the tasks in flight: their workers are stopped, nothing was written
            for pid in self.worker_pids():
                try:
                    os.kill(pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._events.close()


#: How often Ray runs a task again whose worker process or node died under it.
TASK_RETRIES = 3


class RayEngine:
    """The same task function as a Ray task, on a local Ray instance or a cluster."""

    name = "ray"

    def __init__(self, workers: int, address: str | None) -> None:
        try:
            import ray
        except ImportError:
            raise LlcpsError(
                "the ray engine needs Ray, which is not installed", hint="pip install 'llcps[ray]'"
            ) from None
        self._ray = ray
        self.workers = workers
        self._started = not ray.is_initialized()
        if self._started:
            env = {name: "1" for name in THREAD_VARIABLES}
            options: dict[str, Any] = {
                "include_dashboard": False,
                "runtime_env": {"env_vars": env},
                "logging_level": "WARNING",
            }
            if address is None:
                options["num_cpus"] = workers
            try:
                ray.init(address=address, **options)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise LlcpsError(
                    f"cannot start or reach Ray{f' at {address}' if address else ''}: {str(exc).splitlines()[0]}",
                    hint="check --ray-address (e.g. ray://host:10001 or auto), or drop it for a local instance",
                ) from None
        # A task runs against a private scratch store and returns its rows, so one whose
        # worker or node died is run again from the start (a task that raised is not).
        self._remote = ray.remote(num_cpus=1, max_retries=TASK_RETRIES)(execute_task)

    def submit(self, task: Task) -> Any:
        return self._remote.remote(task)

    def wait(self, handles: Iterable[Any], timeout: float) -> list[Any]:
        ready, _ = self._ray.wait(list(handles), num_returns=1, timeout=timeout)
        return list(ready)

    def result(self, handle: Any) -> TaskOutput:
        try:
            return self._ray.get(handle)
        except self._ray.exceptions.RayTaskError as exc:
            cause = exc.as_instanceof_cause()
            raise cause from None

    def past_first_scenario(self) -> set[str]:
        return set()  # Ray tasks do not report it: a twin waits for the whole task

    def close(self, *, abort: bool, pending: Iterable[Any] = ()) -> None:
        if abort:
            for handle in pending:
                try:
                    self._ray.cancel(handle, force=True)
                except Exception:  # noqa: BLE001 - already finished or gone
                    pass
        if self._started:
            self._ray.shutdown()


def make_engine(engine: str, workers: int, *, ray_address: str | None = None) -> LocalEngine | RayEngine:
    """An engine by name (see :data:`ENGINES`)."""
    if engine == "local":
        if ray_address is not None:
            raise LlcpsError("--ray-address needs --engine ray")
        return LocalEngine(workers)
    if engine == "ray":
        return RayEngine(workers, ray_address)
    raise UnknownNameError("engine", engine, ENGINES)


__all__ = ["ENGINES", "Engine", "EngineError", "LocalEngine", "RayEngine", "make_engine"]
