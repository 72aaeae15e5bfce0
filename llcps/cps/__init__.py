"""Creative problem solving, as the paper's agent does it.

- Plan execution and monitoring (:mod:`~llcps.cps.plan_execution`): K's plan runs step by
  step as trials (:mod:`~llcps.cps.executor`, every one stored), the monitor checks each
  step's effects, and a failed step is first repaired by re-planning with what K knows.
- CPS exploration: from the state the failed step a_f ran in (the failure point,
  :mod:`~llcps.cps.failure_point`), the candidates (:mod:`~llcps.cps.candidates`) are a_f
  with other settings on its own arguments (focused), then a_f on other entities and the
  other actions (defocused); the world model W predicts each one's Omega, a measure ranks
  them by it (:mod:`~llcps.cps.ranking`), and an ordering (:mod:`~llcps.cps.orderings`)
  tries the best untried one until one resolves the novelty.
- Learning K' (:mod:`~llcps.cps.learning`): the resolving trial becomes an operator of
  the branch's K' (:mod:`~llcps.cps.branch_knowledge`).
- :mod:`~llcps.cps.episode` runs one episode through all three; random pretraining
  interactions (:mod:`~llcps.cps.pretraining`) give the world model its a-priori data.
"""
