"""The symbolic half: the knowledge base K = <S, A, E, P> of the paper, in PDDL.

- K: the state predicates S, the actions A with their preconditions P and effects E,
  read from and written to PDDL (:mod:`~llcps.symbolic.knowledge_base`, on the lifted
  operators of :mod:`~llcps.symbolic.lifted` and the naive domain of
  :mod:`~llcps.symbolic.pddl_domain`); tasks T = (K, s0, sg) (:mod:`~llcps.symbolic.task`).
- The planner (:mod:`~llcps.symbolic.planner`) and an independent plan validator
  (:mod:`~llcps.symbolic.validate`).
- The execution monitor, which finds the failed action a_f and its missing effects
  (:mod:`~llcps.symbolic.monitor`).
- The learned operators that expand K into K' (:mod:`~llcps.symbolic.operators`),
  costed by experience (:mod:`~llcps.symbolic.experience`).

See docs/knowledge.md.
"""

from __future__ import annotations
