"""The world and the robot's hands and eyes: the sub-symbolic knowledge base Psi of the paper.

- The world: a PyBullet simulation of the table, the Panda arm and the scenario's
  entities (:mod:`~llcps.sim.world`, built from plain scene descriptions in
  :mod:`~llcps.sim.specs`), with exact snapshots (:mod:`~llcps.sim.snapshot`).
- The action controllers R, one per action of K (push, push_together,
  remove_from_container, place_in_container), each with its continuous settings
  (:mod:`~llcps.sim.controllers`, on the motions of :mod:`~llcps.sim.motion`).
- Perception of fluents: the symbolic state s (visible, reachable, touching, on, in,
  holding, near) read from the simulation, and the entity features X of Table 1
  (:mod:`~llcps.sim.perception`); a trial runs a controller between two perceptions
  and yields its meta-outcome Omega (:mod:`~llcps.sim.trial`).
- Random pretraining interactions (:mod:`~llcps.sim.sampler`).
- What the process remembers (idle engines, trusted states), forgotten by
  :func:`llcps.sim.caches.clear_caches`.

See docs/world.md and docs/controllers.md.
"""

