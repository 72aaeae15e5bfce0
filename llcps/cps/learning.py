"""Learning K -> K': the operator a resolving trial teaches, stored on the branch.

Where a_f failed needs no lesson of its own: the failure, counted in a_f's context,
keeps the planner from a_f there (:meth:`KnowledgeBase.allowed`), so it reaches for the
learned operator, followed by the plan it enabled when the trial needed one.
"""

from __future__ import annotations

from llcps.cps.branch_knowledge import BranchExperience
from llcps.cps.executor import TrialExecutor
from llcps.cps.plan_execution import Failure
from llcps.trial_records import TrialRecord, TrialSpec
from llcps.sim.trial import TrialResult
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.operators import learn_operator


def learn(
    executor: TrialExecutor,
    experience: BranchExperience,
    kb: KnowledgeBase,
    spec: TrialSpec,
    trial: TrialResult,
    failure: Failure,
    record: TrialRecord | None,
) -> str:
    """Store the operator the resolving trial ``spec`` teaches and count its execution.

    Returns:
        The learned operator in PDDL, costed by the branch's experience.
    """
    learned = learn_operator(
        spec=spec,
        before=failure.state,
        after=trial.after,
        objects=executor.task(failure.state).objects,
        predicates=kb.predicates,
        focus=failure.step.args,
        replaces=failure.step.name,
    )
    definition = {"operator": learned.to_json(), "refinement": None}
    new_kb = kb.with_operator(learned)
    executor.store.add_operator(
        branch=executor.branch,
        name=learned.name,
        pddl=learned.to_pddl(cost=kb.nominal_cost(failure.step.name)),
        definition=definition,
        scenario=executor.scenario.name,
        episode_id=executor.episode_id,
    )
    known = new_kb.skill(learned)
    step = new_kb.operator(known.name).ground(learned.source_arguments or ())
    context = new_kb.context(step, failure.state) if step is not None else frozenset()
    experience.record(known.name, context, True, record.id if record is not None else None)
    return learned.to_pddl(cost=experience.costed(new_kb).cost(known.name))
