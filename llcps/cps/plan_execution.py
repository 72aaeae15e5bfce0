"""Plan execution and monitoring: K's plan run step by step, repaired when a step fails.

Every step is executed as a trial (:class:`~llcps.cps.executor.TrialExecutor`) and
checked by the monitor for the effects the rest of the plan relies on. When a step
fails, the agent first tries what it already knows: it re-plans from the perceived state
without that ground action (the operator that failed is demoted by its failure, see
:func:`llcps.symbolic.knowledge_base.experience_cost`), executes the repaired plan, and
repeats up to :data:`MAX_PLAN_REPAIRS` times. The first step that failed, a_f, is where
exploration starts (:mod:`llcps.cps.failure_point`), from the snapshot stored before it.

A learned step is K' applied where it was learned to apply, and it can mislead: no fact
may tell the scene from the one it was learned in (an icy table, an arm of shorter reach),
or its facts can hold while the world differs (the object pushed out of reach). So when a
learned step fails, or the step right after it does (a learned operator is planned for the
context it gives the next step), the learned step is *blamed*: it counts as failed where
it ran, and the repair returns the world to where it started and plans there with K alone
(:meth:`~llcps.cps.branch_knowledge.BranchExperience.alone`: no learned operators, costed
by this episode's executions only): the experience that made K's own steps dear there was
gathered where the lesson held, so it is as suspect as the lesson. Later repairs plan
with K alone first too, as a reset agent's would (K' where K alone has no plan, without
the blamed step). Experience misleads the same way without a learned step:
K's own placement, failed in look-alike scenes, is left out where it would work, and K'
plans a *detour* (a push first). So when K's first plan is not the one K alone makes from
the start and it fails, the world returns to the start and K alone plans (this plan is not
counted among the repairs); so does a detour whose failure is blamed on a learned step
after other learned steps that worked: they made the context it was planned for, and
the world they left may be one where K alone fails though it works from the start. A
failure blamed on a learned step or a detour is taken as a_f only when no other is found:
exploration does not start from a state a misleading step left, and it starts where the
reset agent would, with what was learned in its world model.
The re-plan after an exploration trial (:func:`resolves`) falls back on K alone likewise.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Sequence

from llcps.cps.branch_knowledge import BranchExperience
from llcps.cps.executor import TrialExecutor
from llcps.domain import State
from llcps.scenarios.base import Scenario
from llcps.sim.trial import TrialResult
from llcps.symbolic.experience import Context
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.monitor import StepFailure, check_step
from llcps.symbolic.planner import GroundAction, plan

#: Re-plans after the first failed plan step before exploration starts.
MAX_PLAN_REPAIRS = 3


@dataclass(frozen=True)
class StepStart:
    """Where a plan step started: the step, the perceived state, the physics (serialized)
    and the stored snapshot (None when the plan was not stored)."""

    step: GroundAction
    state: State
    physics: bytes
    snapshot: int | None


@dataclass(frozen=True)
class Failure(StepStart):
    """A plan step that failed: where the step a_f started (exploration looks for an
    alternative to a_f from that state) and what the monitor found missing after it."""

    monitor: StepFailure
    #: The learned step blamed for the failure: a_f itself, or the step right before it
    #: (see the module docstring). The repair returns to where it started, without it.
    blamed: StepStart | None = None
    #: The other steps of this episode's plans that missed one of the atoms this step
    #: missed (set on a_f's failure by :func:`plan_and_repair`: K's repairs that tried
    #: for the same atoms another way and failed too; exploration takes them as failed
    #: attempts beside a_f, :mod:`llcps.cps.failure_point`).
    attempts: tuple[GroundAction, ...] = ()

    @property
    def left_out(self) -> tuple[str, tuple[str, ...]]:
        """The ground action a repair plans without: the learned step blamed, else a_f."""
        step = self.blamed.step if self.blamed is not None else self.step
        return (step.name, step.args)


@dataclass(frozen=True)
class PlanRun:
    """How a plan execution ended: the state after the last executed step and, if a step
    failed, the failure; ``started`` is where its first step started."""

    state: State
    failure: Failure | None = None
    started: StepStart | None = None


@dataclass
class PlanLog:
    """What :func:`plan_and_repair` found, written as it goes (an interrupted episode keeps
    what was found before the interruption).

    Attributes:
        plan: K's first plan, as step labels.
        repairs: each repaired plan, the step that failed in it and what it missed, as
            ``solve --json`` prints them.
        failed_action: the first step that failed, a_f (None: no step failed).
        missing_effects: what the monitor found missing after a_f.
        solved: a plan reached the goal.
    """

    plan: list[str] = field(default_factory=list)
    repairs: list[dict[str, object]] = field(default_factory=list)
    failed_action: str | None = None
    missing_effects: str | None = None
    solved: bool = False


def run_plan(
    executor: TrialExecutor,
    steps: Sequence[GroundAction],
    *,
    store: bool = True,
    record: KnowledgeBase | None = None,
    experience: BranchExperience | None = None,
    executed: list[tuple[str, Context, bool, int | None]] | None = None,
) -> PlanRun:
    """Execute a plan step by step with the monitor; stop at the first failing step.

    The monitor checks the effects the plan relies on (causal links): those in the
    goal or needed by a later step's preconditions. A learned operator records every
    change it was seen to make; an incidental one (a neighbour nudged) need not
    recur for the plan to work. Reaching the goal ends the plan early.

    Args:
        steps: the plan.
        store: store each step as a ``plan`` trial (False: nothing is stored, e.g. to
            find where a plan fails).
        record: the knowledge base the plan was made with: count each step in
            ``experience`` as an execution of its operator in its context (success or
            failure), which sets the operator's cost by experience. None: count nothing.
        executed: with ``record``, collect the executions here instead of counting them
            in ``experience`` (the caller counts them if it wants them).
    """
    scenario = executor.scenario
    state = executor.perceive()
    counting = record is not None and store and (experience is not None or executed is not None)
    learned_before: StepStart | None = None  # the previous step, if it was a learned one that worked
    started: StepStart | None = None
    held: tuple[str, Context, bool, int | None] | None = None  # its execution, counted once the next step shows

    def count(execution: tuple[str, Context, bool, int | None]) -> None:
        if executed is not None:
            executed.append(execution)
        else:
            assert experience is not None
            experience.record(*execution)

    for index, step in enumerate(steps):
        spec = executor.controller_call(step)
        if store:
            stored = executor.snapshot()
            physics = executor.snapshot_state(stored)
        else:
            stored, physics = None, executor.checkpoint()
        trial, trial_record = executor.execute(spec, source="plan", snapshot_id=stored)
        reached = scenario.goal_reached(trial.after)
        learned = record is not None and record.is_learned(step.name)
        failure = None if reached else check_step(_relied_on(step, steps[index + 1 :], scenario, learned=learned), trial.after)
        if held is not None:  # a learned step worked if the step it was planned for did
            count(held if failure is None else (*held[:2], False, held[3]))
            held = None
        if counting:
            assert record is not None
            execution = (step.name, record.context(step, trial.before), failure is None, trial_record.id if trial_record is not None else None)
            if learned and failure is None and not reached and index + 1 < len(steps):
                held = execution
            else:
                count(execution)
        start = StepStart(step, trial.before, physics, stored)
        started = started or start
        if reached:
            return PlanRun(trial.after, started=started)
        if failure is not None:
            failed = Failure(step, trial.before, physics, stored, failure, blamed=start if learned else learned_before)
            return PlanRun(trial.after, failed, started)
        learned_before = start if learned else None
        state = trial.after
    return PlanRun(state, started=started)


def _relied_on(step: GroundAction, later: Sequence[GroundAction], scenario: Scenario, *, learned: bool = False) -> GroundAction:
    """``step`` with only the effects the goal or a later step's preconditions need.

    A ``learned`` operator's facts about a later step's arguments are needed too: it is
    planned for the context it gives the step it was learned to make work (the planner
    judges that step by the facts of its arguments, :meth:`KnowledgeBase.allowed`), even
    when no precondition names them. Bound to the wrong object (a block where a can was
    learned) it leaves that context unmade, and the monitor must see it fail there, not
    at the step after it.
    """
    needed_true = set(scenario.goal_pos).union(*(s.preconditions for s in later))
    if learned:
        needed_true.update(atom for atom in step.add if any(set(atom[1:]) <= set(s.args) for s in later))
    needed_false = set(scenario.goal_neg).union(*(s.negative_preconditions for s in later))
    return replace(step, add=step.add & needed_true, delete=step.delete & needed_false)


def plan_and_repair(
    executor: TrialExecutor,
    experience: BranchExperience,
    kb: KnowledgeBase,
    state: State,
    log: PlanLog,
    *,
    store: bool = True,
) -> Failure | None:
    """Execute K's plan; on a failed step re-plan without it, up to MAX_PLAN_REPAIRS times.

    Every executed step is a stored ``plan`` trial and counts as an execution of its
    operator, so a step that fails is demoted before the re-plan. Writes K's first plan,
    the repairs, the first failure and whether a plan reached the goal to ``log``. With
    ``store=False`` nothing is stored or counted (the path ``llcps inspect model`` takes
    to the failure point); the failed steps are still left out of the re-plans.

    Experience never leaves K without a first plan (the planner runs again with the
    steps experience left out allowed, :func:`llcps.symbolic.planner.plan`): a step
    that failed in a context like this one is planned, dearer, fails again, and gives a_f.

    A failure blamed on a learned step (:attr:`Failure.blamed`) is repaired from where
    that step started, with K alone; a first plan that K alone would not have made (a
    detour) is, when it fails (blamed or not), followed by K alone's plan from the start. a_f is the
    first failure not blamed on a learned step or a detour, else the first such one.

    Returns:
        a_f's failure, or None when no step failed. Exploration looks for an
        alternative to its step a_f from the state a_f was executed in; the failure's
        ``attempts`` are the repairs' steps that missed a_f's missing atoms too.
    """
    first: Failure | None = None
    misled: Failure | None = None  # the first failure blamed on a learned step or on a detour
    failures: list[Failure] = []
    excluded: set[tuple[str, tuple[str, ...]]] = set()
    alone_first = False  # K alone plans first: after a blamed learned step or a detour
    detour = False  # K' planned otherwise from the start than K alone would
    rewound = False  # the world was returned to an earlier state before this plan
    attempt = 0
    while attempt <= MAX_PLAN_REPAIRS:
        opening = attempt == 0 and not rewound
        executor.report("plan" if opening else "re-plan")
        for known in ([experience.alone(kb)] if alone_first else []) + [experience.costed(kb)]:
            steps = plan(known, executor.task(state), exclude=excluded, last_resort=attempt == 0)
            if steps is not None:
                break
        if steps is None:
            break
        labels = [step.label for step in steps]
        if opening:
            log.plan = labels
            reset_plan = plan(experience.alone(kb), executor.task(state), last_resort=True) if experience.taught(kb) else None
            detour = reset_plan is not None and [step.label for step in reset_plan] != labels
        run = run_plan(executor, steps, store=store, record=known, experience=experience)
        state, failure = run.state, run.failure
        if failure is not None:
            failures.append(failure)
        if not opening:
            log.repairs.append(
                {
                    "plan": labels,
                    "rewound": rewound,
                    "failed_action": failure.step.label if failure is not None else None,
                    "missing_effects": failure.monitor.describe() if failure is not None else None,
                }
            )
        if failure is None:
            if executor.scenario.goal_reached(state):
                log.solved = True
            return with_attempts(first or misled, failures)
        # a detour goes back to its start, even past learned steps that worked: they made
        # the context the blamed one was planned for, and K alone plans from the start
        back_to = run.started if detour else failure.blamed
        detour = rewound = False
        if failure.blamed is not None or back_to is None:
            excluded.add(failure.left_out)
            attempt += 1
        if back_to is not None:  # back to where the learned step or the detour started
            misled = misled or failure
            executor.resume(back_to.physics)
            state, alone_first, rewound = back_to.state, True, True
        elif first is None:
            first = failure
        if (first or misled) is failure:
            log.failed_action = failure.step.label
            log.missing_effects = failure.monitor.describe()
    return with_attempts(first or misled, failures)


def with_attempts(found: Failure | None, failures: Sequence[Failure]) -> Failure | None:
    """``found`` (a_f's failure) with :attr:`Failure.attempts`: the steps of ``failures``
    that missed one of the atoms a_f missed, other than a_f's own action on its
    arguments, each ground action once, in the order they failed."""
    if found is None:
        return None
    missing = found.monitor.missing_add | found.monitor.missing_del
    own = (found.step.name, found.step.args)
    attempts: dict[tuple[str, tuple[str, ...]], GroundAction] = {}
    for failure in failures:
        key = (failure.step.name, failure.step.args)
        if key != own and missing & (failure.monitor.missing_add | failure.monitor.missing_del):
            attempts.setdefault(key, failure.step)
    return replace(found, attempts=tuple(attempts.values()))


def find_failure(executor: TrialExecutor, experience: BranchExperience, kb: KnowledgeBase, log: PlanLog) -> Failure | None:
    """Perceive; unless the goal holds already, execute K's plan with its repairs
    (:func:`plan_and_repair`, every step stored).

    Returns:
        The first failure, a_f, where exploration starts; None when no step failed
        (``log.solved`` then says whether the goal was reached).
    """
    state = executor.perceive()
    if executor.scenario.goal_reached(state):
        log.solved = True
        return None
    return plan_and_repair(executor, experience, kb, state, log)


def resolves(
    executor: TrialExecutor, experience: BranchExperience, kb: KnowledgeBase, trial: TrialResult, failure: Failure, *, count: bool = True
) -> bool:
    """Did this trial resolve the novelty?

    A trial resolves it if the goal now holds, or if K' (costed by experience) plans from
    the new state and that plan, executed, reaches the goal, or, when the plans of K' fail, K
    alone's (:meth:`~llcps.cps.branch_knowledge.BranchExperience.alone`; a plan already
    run from there is not run again): a plan K made from the
    failure point itself started with a_f, which failed there, so a plan that works now
    works because of the trial. The plan is repaired as K's first plan was
    (:func:`plan_and_repair`): a step that fails is left out and K plans again, up to
    :data:`MAX_PLAN_REPAIRS` times, so a trial that clears the way for a step K reaches
    only by a repair resolves the novelty too. Each repaired plan starts from the state
    the trial left (restored), not from where the failed step left the world: what
    resolves is the trial followed by that plan, the lesson K' records, and not a side
    effect of a step that failed (the snapshot is the one the plan's first step takes:
    the store keeps a state once). Only a trial that changed a fact about an entity of
    a_f or of the goal is followed by a re-plan: other changes cannot have made a plan
    work that did not before. The steps of a re-plan that works count as executions of
    their operators where they ran (a_f working after the trial, in the trial's context;
    a step a repair left out, failing), so that the planner knows the chain of the
    learned operator and the plan it enabled; those of a re-plan that fails count nothing
    (exploration is not K's plan failing).
    ``count=False`` counts nothing at all (a sweep judges every candidate alone).
    """
    scenario = executor.scenario
    if scenario.goal_reached(trial.after):
        return True
    focus = set(failure.step.args) | {t for atom in scenario.goal_pos | scenario.goal_neg for t in atom[1:]}
    changed = trial.after ^ failure.state
    if not any(focus.intersection(atom[1:]) for atom in changed):
        return False
    executed: list[tuple[str, Context, bool, int | None]] = []
    left = executor.snapshot()  # the state the trial left: every repaired plan starts there
    ran: dict[tuple[str, ...], PlanRun] = {}  # what each plan did from there (the physics is deterministic)
    for known in experience.knowledge(kb):
        excluded: set[tuple[str, tuple[str, ...]]] = set()
        for _ in range(1 + MAX_PLAN_REPAIRS):
            steps = plan(known, executor.task(trial.after), exclude=excluded)
            if not steps:
                break
            labels = tuple(step.label for step in steps)
            if labels not in ran:
                if ran:
                    executor.restore(left)
                executor.report("re-plan")
                ran[labels] = run_plan(executor, steps, record=known, executed=executed)
            run = ran[labels]
            if run.failure is None:
                break
            excluded.add(run.failure.left_out)
        if steps and run.failure is None:
            break
    else:
        return False
    resolved = run.failure is None and scenario.goal_reached(run.state)
    if resolved and count:  # the plan the trial enabled worked: K's steps count where they ran, failed steps of its repairs too
        for execution in executed:
            experience.record(*execution)
    return resolved
