"""The trial executor: one world, the trials run in it, and their rows in the store.

A :class:`TrialExecutor` runs every trial of an episode (plan steps and exploration
alike), answers it from the physics cache where the cache knows it, writes it to the
store as it happens, and keeps the lifelong training set the world model refits on.
It also maps K's plan steps to controller calls (K's nominal settings) and the
perceived state to a PDDL task.

**The lazy world state.** A stored trial leaves the world in its serialized end state,
so what follows is the same whether the trial was simulated or answered by the cache.
Loading those bytes rebuilds the world, which is the dearest thing a cached trial
costs, so the executor defers it: the world continues from the end state, loaded when
it is next used (:meth:`TrialExecutor.sync`) and not at all when a restore of another
state comes first. What is read from a world still to be loaded (the bytes it saves,
what perceiving it gives, a push's approach side) is a function of those bytes and the
scene alone, so it is kept in :class:`WorldReads`, shared by the executors of a process.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from collections.abc import MutableMapping
from dataclasses import dataclass, replace
from typing import Any, Callable, Hashable, TypeVar

import numpy as np

from llcps.domain import PUSH_DIRECTION, ControllerParams, State
from llcps.trial_records import TrialChange, TrialRecord, TrialSpec
from llcps.training import TrainingSet
from llcps.errors import LlcpsError
from llcps.scenarios.base import Scenario
from llcps.scenarios.goal import goal_text
from llcps.sim.cache import CachedTrial, PhysicsCache, trial_key
from llcps.sim.controllers import DEFAULT_MAX_STEPS
from llcps.sim.perception import perceive
from llcps.sim.trial import TrialResult, bodies_met, run_trial
from llcps.sim.world import SavedState, World
from llcps.store import Store
from llcps.symbolic.lifted import GroundAction
from llcps.symbolic.task import Task

#: Controller settings of K's own actions: the robot's nominal way of doing each.
NOMINAL_RATE = 0.4
NOMINAL_MAGNITUDE = 0.15
#: Push directions K may use to move an object toward a target ("top" tips it instead).
PUSH_DIRECTIONS = {k: v for k, v in PUSH_DIRECTION.items() if k != "top"}

T = TypeVar("T")

ProgressCallback = Callable[[str, int, int], None]
"""Called as ``progress(phase, done, total)``: phase is "fit world model NAME", "plan",
"explore", "re-plan" or "render"; done and total count exploration trials (total 0: not
known yet), or frames while rendering."""


class WorldReads:
    """What was read from worlds still to be loaded from a serialized end state (and
    perceived, where they were), by scene key, digest of the end state and query; the
    least recently used go first beyond ``capacity`` entries.

    Attributes:
        capacity: most reads kept (0: none; every read loads the world).
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self._reads: OrderedDict[Hashable, Any] = OrderedDict()

    def __len__(self) -> int:
        return len(self._reads)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._reads

    def get(self, key: Hashable) -> Any:
        """The read kept under ``key`` (it must be there), now the most recently used."""
        self._reads.move_to_end(key)
        return self._reads[key]

    def put(self, key: Hashable, value: Any) -> None:
        """Keep ``value`` under ``key``, dropping the least recently used beyond capacity."""
        self._reads[key] = value
        while len(self._reads) > self.capacity:
            self._reads.popitem(last=False)

    def clear(self) -> None:
        """Forget every read."""
        self._reads.clear()


#: The reads every executor of this process shares: up to ~40 kB a serialized state,
#: at most ~80 MB.
WORLD_READS = WorldReads(capacity=2048)


@dataclass
class TrialTally:
    """What an executor's stored trials add up to, as they are stored."""

    sim_steps: int = 0
    cache_hits: int = 0
    plan_trials: int = 0
    exploration_trials: int = 0


class TrialExecutor:
    """Executes trials in one world and records each one in the store.

    Attributes:
        records: the trials the branch sees, this episode's appended as they are stored
            (the world model's lifelong training set; the store's own is read only when needed).
        changes: the known symbolic change of each trial in ``records``, by trial id.
        kinds: entity name -> kind (``object`` or a container kind).
        tally: what the stored trials add up to.
        max_steps: the step cap of every trial: the one the physics runs under and the
            cache keys by.
    """

    def __init__(
        self,
        *,
        store: Store,
        branch: str,
        world: World,
        scenario: Scenario,
        seed: int,
        run_id: int | None = None,
        episode_id: int | None = None,
        records: TrainingSet | None = None,
        changes: MutableMapping[int, TrialChange] | None = None,
        cache: PhysicsCache | None = None,
        max_steps: int = DEFAULT_MAX_STEPS,
        progress: ProgressCallback | None = None,
        reads: WorldReads = WORLD_READS,
    ) -> None:
        self.store = store
        self.branch = branch
        self.world = world
        self.scenario = scenario
        self.seed = seed
        self.run_id = run_id
        self.episode_id = episode_id
        self.records = TrainingSet.of([]) if records is None else records
        self.changes: MutableMapping[int, TrialChange] = {} if changes is None else changes
        self.kinds = {name: entity.spec.kind for name, entity in world.entities.items()}
        self.cache = cache
        self.max_steps = max_steps
        self.tally = TrialTally()
        self._progress = progress
        self._explore_total = 0
        self._reads = reads
        # Physics state of each stored snapshot this executor took, by snapshot id.
        self._states: dict[int, bytes] = {}
        # The serialized end state of the last stored trial (a SavedState when this
        # process simulated it): the world continues from exactly these bytes, loaded
        # when it is next used (unless a restore comes first).
        self._pending: bytes | SavedState | None = None
        # Set when the world, still to be loaded from _pending, has also been perceived
        # (see perceive): the serialized state it then has.
        self._perceived: bytes | None = None

    def report(self, phase: str, *, total: int | None = None) -> None:
        """Tell the progress callback the phase and the exploration trials done so far."""
        if total is not None:
            self._explore_total = total
        if self._progress is not None:
            self._progress(phase, self.tally.exploration_trials, self._explore_total)

    # -- symbolic glue -------------------------------------------------------
    def task(self, state: State) -> Task:
        """The scenario's task from ``state``, over this world's entities and fixtures."""
        return Task.from_scene(
            entities=self.kinds, fixtures=self.world.fixtures, init=state, goal_pos=self.scenario.goal_pos, goal_neg=self.scenario.goal_neg
        )

    def controller_call(self, step: GroundAction) -> TrialSpec:
        """Map a plan step to its controller call: learned settings, or K's nominal ones."""
        call = step.controller
        if call is None:
            raise LlcpsError(f"plan step {step.label} has no controller")
        orientation = "top"
        if call.action == "push" and call.toward is not None:
            obj, target = call.arguments[0], call.toward
            orientation = self.remembered(("toward", obj, target), lambda: self.orientation_toward(obj, target))
        return call.spec(ControllerParams(NOMINAL_RATE, NOMINAL_MAGNITUDE, orientation))

    def orientation_toward(self, obj: str, target: str) -> str:
        """K's push moves ``obj`` toward ``target``: the approach side whose push does."""
        a = np.asarray(self.world.center(obj)[:2])
        b = np.asarray(self.world.center(target)[:2])
        d = b - a
        return max(PUSH_DIRECTIONS, key=lambda k: float(np.dot(PUSH_DIRECTIONS[k], d)))

    # -- trials ----------------------------------------------------------------
    def execute(
        self, spec: TrialSpec, *, source: str, snapshot_id: int | None, start: int | None = None
    ) -> tuple[TrialResult, TrialRecord | None]:
        """Run one trial and store it durably.

        The trial starts from the stored snapshot ``start`` if given, else from the
        world's current state, which must then be the state of ``snapshot_id``. With
        ``snapshot_id=None`` the trial is not stored (nor answered by the cache).
        A stored trial leaves the world in its serialized end state, so what follows
        is the same whether the trial was simulated or answered by the physics cache;
        a cached answer is recorded as such, with this run's wall seconds.
        """
        started = time.perf_counter()
        cached: CachedTrial | None = None
        key: str | None = None
        if snapshot_id is not None and self.cache is not None:
            key = trial_key(self.world.settings, self.world.scene.to_dict(), self._states[snapshot_id], spec, self.max_steps)
            # The end state comes from the database: checked like a stored snapshot (a state
            # this process made, or checked before, or sealed by this machine costs a digest).
            cached = self.cache.get(key, check=self.world.check_serialized, trust=self.world.trust_serialized)
            if cached is not None and cached.result.spec != spec:  # a damaged entry: simulate instead
                cached = None
            if cached is None and start is None:
                start = snapshot_id  # a check may have rebuilt the world: start from the stored bytes
        if cached is not None:
            trial = cached.result
            self._continue_from(cached.end_state)
        else:
            if start is not None:
                self.restore(start)
            else:
                self.sync()
            trial = run_trial(self.world, spec, max_steps=self.max_steps)
            if snapshot_id is None:
                return trial, None
            # Continue from exactly the stored bytes; the restore waits until the world is
            # used again, and is skipped when a restore of another state comes first.
            self._continue_from(self.world.save())  # compressed only if stored or remembered
            if key is not None:
                self.cache.put(key, trial, self._serialized_pending())
        new = TrialRecord.from_result(
            trial,
            branch=self.branch,
            source=source,
            seed=self.seed,
            solved=self.scenario.goal_reached(trial.after),
            run_id=self.run_id,
            episode_id=self.episode_id,
            snapshot_id=snapshot_id,
            scenario=self.scenario.name,
            wall_seconds=trial.wall_seconds if cached is None else time.perf_counter() - started,
            cache_hit=cached is not None,
            simulation_wall_seconds=trial.wall_seconds,
        )
        change = trial.change
        trial_id = self.store.add_trial(new, change=change)
        record = replace(new, id=trial_id)
        self.records.append(record)
        self.changes[trial_id] = replace(change, trial_id=trial_id)
        self.tally.sim_steps += trial.sim_steps
        if cached is not None:
            self.tally.cache_hits += 1
        if source == "plan":
            self.tally.plan_trials += 1
        elif source == "exploration":
            self.tally.exploration_trials += 1
        return trial, record

    # -- the world's state ------------------------------------------------------
    def snapshot(self) -> int:
        """Save the world's physics state in the store; returns the snapshot id."""
        state = self.checkpoint()
        stored = self.store.put_snapshot(scene=self.scene_record(), state=state)
        self._states[stored] = state
        return stored

    def snapshot_state(self, snapshot_id: int) -> bytes:
        """The physics state of a snapshot this executor took."""
        return self._states[snapshot_id]

    def checkpoint(self) -> bytes:
        """The world's state serialized (:meth:`World.serialize_state`'s bytes); the world
        continues from exactly these bytes, loaded when it is next used (see :meth:`sync`).

        With an end state still to be loaded, the bytes its restore would save are
        :meth:`remembered`: when the next trial is answered by the physics cache, the
        world is not rebuilt at all.
        """
        if self._perceived is not None:
            state = self._perceived
        else:
            state = self.remembered(("save",), self.world.save_state)
            if self._pending is not None:
                self.world.trust_serialized(state)  # this process saved it
        self._continue_from(state)
        return state

    def perceive(self) -> State:
        """The symbolic state of the world (:func:`~llcps.sim.perception.perceive`).

        Perception probes the arm (IK), which changes what the world saves next. With
        an end state still to be loaded, what it perceives and what the world then
        saves are :meth:`remembered`; nothing is loaded, :meth:`checkpoint` gives the
        saved bytes, and :meth:`sync` loads the end state and perceives it again.
        """
        if self._perceived is not None:
            self.sync()
        state, saved = self.remembered(("perceive",), lambda: (perceive(self.world), self.world.save_state()))
        if self._pending is not None:  # remembered: the world was not loaded
            self._perceived = saved
            self.world.trust_serialized(saved)  # this process saved it
        return state

    def remembered(self, query: tuple[object, ...], read: Callable[[], T]) -> T:
        """``read()`` of the world as it stands.

        While the world is still to be loaded from an end state, the result is a
        function of those bytes and the scene, so it is kept in the :class:`WorldReads`
        under ``query`` and the world is loaded (:meth:`sync`) only the first time.
        ``read`` must not change what the world saves next, unless its caller accounts
        for it (see :meth:`perceive`).
        """
        if self._pending is None:
            return read()
        digest = hashlib.sha256(self._serialized_pending()).hexdigest()
        key = (self.world.scene_key, digest, self._perceived is not None, *query)
        if key in self._reads:
            return self._reads.get(key)  # type: ignore[no-any-return]
        self.sync()
        value = read()
        self._reads.put(key, value)
        return value

    def scene_record(self) -> dict[str, object]:
        """The scene as a snapshot stores it: what the world is built from, and the task's goal,
        so that a trial replays (and is judged) from the store alone, whatever file it came from."""
        return {**self.world.scene.to_dict(), "goal": goal_text(self.scenario.goal_pos, self.scenario.goal_neg)}

    def met(self, spec: TrialSpec) -> frozenset[str]:
        """The bodies ``spec``'s stroke meets from the world's state now
        (:func:`~llcps.sim.trial.bodies_met`), simulated and not stored; restore a
        snapshot after it."""
        self.sync()
        return bodies_met(self.world, spec, max_steps=self.max_steps)

    def restore(self, snapshot_id: int) -> None:
        """Return the world to a snapshot taken by :meth:`snapshot`."""
        self.resume(self._states[snapshot_id])

    def resume(self, state: bytes) -> None:
        """Return the world to serialized bytes this executor saved (:meth:`checkpoint`,
        or a snapshot's :meth:`snapshot_state`)."""
        self._pending = self._perceived = None
        self.world.restore_serialized(state)

    def sync(self) -> None:
        """Bring the world to the serialized end state of the last stored trial (and
        perceived, if :meth:`perceive` was answered without it), if not done yet."""
        if self._pending is not None:
            state, perceived, self._pending, self._perceived = self._pending, self._perceived, None, None
            if isinstance(state, SavedState):
                self.world.restore_saved(state)
            else:
                self.world.restore_serialized(state)
            if perceived is not None:
                perceive(self.world)  # what it did to the world, again

    def _continue_from(self, state: bytes | SavedState) -> None:
        """The world goes on from exactly ``state``, loaded when it is next used."""
        self._pending, self._perceived = state, None

    def _serialized_pending(self) -> bytes:
        """The end state still to be loaded, as serialized bytes."""
        state = self._pending
        assert state is not None
        return state.serialized if isinstance(state, SavedState) else state
