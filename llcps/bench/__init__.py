"""How close each layer comes to the physics bound: the figures ``llcps bench`` prints.

llcps exists to run many exploration trials, and physics bounds how fast it can. Each
group measures one cost of the paper's loop with the code the agent itself runs and
returns :class:`Figure` rows; a figure with a ``target`` says whether it was met.
Figures are measurements to report (docs/performance.md), never test assertions.

The groups against the paper (``GROUPS``; one module each):

- ``physics`` (:mod:`llcps.bench.physics`): the physics bound on a trial, the raw
  step and control-loop (IK + motors + step) rates of every scenario's scene.
- ``exploration`` (:mod:`llcps.bench.exploration`): the cost of an exploration
  episode, a real ``solve`` against the control-loop rate of its scene, and where
  its CPU time goes besides the control loop.
- ``models`` (:mod:`llcps.bench.models`): the cost of fitting W : (a, r, ∇, X) → Ω,
  fit / update with one more trial / predict of every registered world model.
- ``ranking`` (:mod:`llcps.bench.ranking`): the cost of ranking with W's
  predictions, 1,000 candidates ordered under every measure.
- ``store`` (:mod:`llcps.bench.store`): the experience store's throughput, durable
  commits, batched inserts and the visible set of a branch three levels deep.
- ``life`` (:mod:`llcps.bench.life`): the per-episode overhead outside physics (fit,
  rank, store) at episodes 10, 100 and 1,000 of a synthetic life, and the store of a
  long life: 1,000,000 trials' visible set read as columns (and as records), durable
  commits on it.
- ``scaling`` (:mod:`llcps.bench.scaling`): the experiment grid on 1 and 2 worker
  processes, with and without the physics cache.

:mod:`llcps.bench.core` holds what they share: figures and targets, clocks, the
steadiness checks (:func:`unsteady`, :func:`judged`) and :func:`run_bench`, which
loads a group's module only when the group runs.

Rates are given per second of *CPU time* of this process (``time.process_time``)
as well as of wall-clock time: other jobs on a shared machine slow the wall clock
but not the CPU time, so the CPU figures are the stable ones to compare.
"""

from __future__ import annotations

from llcps.bench.core import GROUPS, NOT_JUDGED, SLOW_GROUPS, Figure, Progress, figure, judged, run_bench, unsteady

__all__ = [
    "GROUPS",
    "NOT_JUDGED",
    "SLOW_GROUPS",
    "Figure",
    "Progress",
    "figure",
    "judged",
    "run_bench",
    "unsteady",
]
