"""What ``llcps inspect model`` shows: held-out metrics next to the majority baseline,
the training set's label frequencies, and optionally the top candidates of a
scenario's failure point under each measure, with each candidate's predicted
probability of the failure's missing atoms.

The failure point is reached the way the agent reaches it (:func:`~llcps.cps.plan_execution.plan_and_repair`,
then :func:`~llcps.cps.failure_point.failure_point` from the state a_f was executed in),
without storing anything (except the fitted models, stored by
:func:`~llcps.models.persistence.fit_or_load`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from llcps.cps.failure_point import FailurePoint, failure_point
from llcps.cps.ranking import rank_candidates
from llcps.domain import OUTCOME_NAMES, check_seed
from llcps.errors import LlcpsError
from llcps.models.base import WorldModel
from llcps.models.evaluation import EvaluationReport, evaluate
from llcps.models.features import outcome_matrix
from llcps.models.goal import joint_probability
from llcps.models.measures import MEASURES
from llcps.models.persistence import fit_or_load
from llcps.models.registry import world_model_entry

if TYPE_CHECKING:
    from llcps.store import Store


class PlanSucceeds(LlcpsError):
    """The scenario's novelty plan reaches the goal on the branch: there is no failure
    state whose candidates could be ranked."""


@dataclass(frozen=True)
class RankedCandidate:
    """One candidate trial in a measure's order, with the predictions it was ranked by.

    Attributes:
        goal: predicted probability of each missing atom (``+(in a b)`` must become
            true, ``-(in a b)`` must stop), and ``joint`` their product.
        claimed: the missing atoms the knowledge base claims the candidate's action has
            as an effect (the goal head's prior, docs/world_models.md).
        subgoals: predicted probability that the candidate meets each subgoal (another
            step of K and the preconditions it lacks, :mod:`llcps.cps.failure_point`).
        resolve: the probability ``goal-directed`` ranks by: the missing atoms, or a
            subgoal and K's step after it.
        refused: the arm would refuse the call here (the reach check): the agent tries
            it after every other candidate, whatever its score.
    """

    position: int
    trial: str
    score: float
    outcome: dict[str, float]
    goal: dict[str, float]
    joint: float
    claimed: tuple[str, ...] = ()
    subgoals: dict[str, float] = field(default_factory=dict)
    resolve: float | None = None
    refused: bool = False


@dataclass(frozen=True)
class ModelInspection:
    """Everything ``llcps inspect model`` reports."""

    branch: str
    seed: int
    n_trials: int
    label_frequencies: dict[str, float]
    evaluations: tuple[EvaluationReport, ...]
    failure: FailurePoint | None = None
    #: model -> measure -> the top candidates, best first.
    rankings: dict[str, dict[str, list[RankedCandidate]]] = field(default_factory=dict)
    #: Why there are no held-out metrics (too few trials), if so.
    evaluation_note: str | None = None
    #: Trials the goal-aware heads could learn from (those with a known change).
    n_changes: int = 0
    #: The scene variant the failure point was reached in.
    variant: int = 0
    #: Why a scenario asked for has no ranking (its plan succeeds on the branch), and
    #: how to rank it anyway.
    ranking_note: str | None = None
    ranking_hint: str | None = None

    def as_json(self) -> dict[str, Any]:
        data: dict[str, Any] = {
            "branch": self.branch,
            "seed": self.seed,
            "n_trials": self.n_trials,
            "n_changes": self.n_changes,
            "label_frequencies": self.label_frequencies,
            "evaluations": [report.as_json() for report in self.evaluations],
            "evaluation_note": self.evaluation_note,
        }
        if self.ranking_note is not None:
            data["ranking_note"] = self.ranking_note
            data["ranking_hint"] = self.ranking_hint
        if self.failure is not None:
            data["scenario"] = {
                "name": self.failure.scenario,
                "variant": self.variant,
                "failed_action": self.failure.failure.step.label,
                "missing_effects": self.failure.missing_effects,
                "missing_atoms": [atom.label for atom in self.failure.query([]).atoms],
                "subgoals": [subgoal.label for subgoal in self.failure.subgoals],
                "met": list(self.failure.met),
                "in_the_way": len(self.failure.in_the_way),
                "relocations": len(self.failure.relocations),
                "desired": dict(zip(OUTCOME_NAMES, self.failure.desired.round(4).tolist())),
                "candidates": len(self.failure.candidates),
                "refused": len(self.failure.refused),
                "rankings": {
                    model: {measure: [asdict(c) for c in ranked] for measure, ranked in by_measure.items()}
                    for model, by_measure in self.rankings.items()
                },
            }
        return data


def top_candidates(model: WorldModel, point: FailurePoint, *, measure: str, top: int, seed: int) -> list[RankedCandidate]:
    """The first ``top`` candidates of a failure point in the order the agent tries them
    under ``measure`` (those the arm would refuse, :attr:`FailurePoint.refused`, after the
    rest in candidate order), with their predictions."""
    ranking = rank_candidates(model, point, measure=measure, seed=seed)
    order = [int(i) for i in ranking.order if i not in point.refused] + sorted(point.refused)
    goal = ranking.goal if ranking.goal is not None else model.predict_goal(point.query())
    atoms = [atom.label for atom in point.query([]).atoms]
    joint = joint_probability(goal)
    subgoals = [s.label for s in point.subgoals]
    return [
        RankedCandidate(
            position=position + 1,
            trial=point.candidates[i].label,
            score=round(float(ranking.score[i]), 6),
            outcome={name: round(float(p), 4) for name, p in zip(OUTCOME_NAMES, ranking.outcome[i])},
            goal={atom: round(float(p), 4) for atom, p in zip(atoms, goal[i])},
            joint=round(float(joint[i]), 6),
            claimed=tuple(a.label for a in point.query([i]).atoms if (a.atom, a.add) in (point.claimed[i] if point.claimed else ())),
            subgoals={} if ranking.subgoals is None else {s: round(float(p), 4) for s, p in zip(subgoals, ranking.subgoals[i])},
            resolve=None if ranking.resolve is None else round(float(ranking.resolve[i]), 6),
            refused=i in point.refused,
        )
        for position, i in enumerate(order[:top])
    ]


def reach_failure(
    store: Store, *, branch: str, scenario: str, seed: int, variant: int = 0, reach_check: bool = True
) -> FailurePoint:
    """Run ``scenario``'s novelty plan and its repairs (nothing stored) in scene ``variant``
    to the failure exploration starts from, as the agent does (``reach_check``: find the
    candidates the arm would refuse there, as the agent does by default).

    Raises:
        LlcpsError: unknown scenario or no plan; :class:`PlanSucceeds` for a plan (or a
            repair) that reaches the goal.
    """
    # The agent's machinery (PyBullet, planner) loads only when a scenario is asked for.
    from llcps.cps.branch_knowledge import BranchExperience, load_knowledge
    from llcps.cps.episode import SolveConfig
    from llcps.cps.executor import TrialExecutor
    from llcps.cps.plan_execution import PlanLog, plan_and_repair
    from llcps.sim.perception import perceive
    from llcps.sim.world import SETTLE_STEPS, World

    config = SolveConfig(scenario=scenario, seed=seed, variant=variant)
    spec = config.validate()
    world = World.from_scene(spec.scene("novelty", config.variant))
    try:
        world.settle(max_steps=SETTLE_STEPS)
        executor = TrialExecutor(store=store, branch=branch, world=world, scenario=spec, seed=seed)
        experience = BranchExperience(store, branch)
        kb = load_knowledge(store, branch)
        log = PlanLog()
        failure = plan_and_repair(executor, experience, kb, perceive(world), log, store=False)
        if failure is None and not log.solved:
            raise LlcpsError(f"the knowledge base of {branch!r} has no plan for {spec.name}'s novelty condition")
        if failure is None or log.solved:
            learned = bool(store.visible_operators(branch))
            raise PlanSucceeds(
                f"the plan for {spec.name}'s novelty condition succeeds on {branch!r}: no failure state to rank",
                hint="the branch has learned operators that resolve it; to rank anyway, fork a branch at the "
                "pretraining point and inspect it: `llcps db branch before --at pretrain`, then "
                f"`llcps --branch before inspect model --scenario {spec.name}`"
                if learned
                else "the novelty does not make the nominal plan fail (see docs/scenarios.md)",
            )
        world.restore_serialized(failure.physics)  # what a_f's stroke met, as the agent sees it
        met = executor.met(executor.controller_call(failure.monitor.step))
        world.restore_serialized(failure.physics)  # candidates start where a_f did
        return failure_point(
            executor, failure.monitor, failure.state, kb, grid=config.candidate_grid(spec), known=experience.costed(kb),
            reach_check=reach_check, attempts=failure.attempts, met=met,
        )  # fmt: skip
    finally:
        world.close()


def inspect_models(
    store: Store,
    *,
    branch: str,
    models: Sequence[str],
    seed: int,
    test_fraction: float = 0.25,
    scenario: str | None = None,
    top: int = 5,
    model_seed: int | None = None,
    variant: int = 0,
    reach_check: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
) -> ModelInspection:
    """Evaluate ``models`` on the branch's trials and, with a scenario, rank its candidates.

    Args:
        store: the experience store.
        branch: whose visible trials train and test the models.
        models: WORLD_MODELS names.
        seed: seeds the held-out split and tie-breaks (and the models, without ``model_seed``).
        test_fraction: share of trials held out for the metrics.
        scenario: a scenario whose failure point's candidates to rank (optional).
        top: candidates shown per measure.
        model_seed: seed of the world models (None: ``seed``).
        variant: the scene variant of ``scenario`` (0: the canonical scene).
        reach_check: list the candidates the arm would refuse last, as the agent tries them.
        progress: called as ``progress(phase, done, total)`` as the work goes on.
    """
    check_seed(seed)
    fit_seed = seed if model_seed is None else check_seed(model_seed, "model seed")

    def say(phase: str, done: int = 0, total: int = 0) -> None:
        if progress is not None:
            progress(phase, done, total)

    for name in models:
        world_model_entry(name)
    if top < 1:
        raise LlcpsError(f"--top must be at least 1, got {top}")
    failure = None
    ranking_note = ranking_hint = None
    if scenario is not None:  # before any fit: a plan that succeeds has nothing to rank
        say(f"{scenario}: running the plan to its failure")
        try:
            failure = reach_failure(store, branch=branch, scenario=scenario, seed=seed, variant=variant, reach_check=reach_check)
        except PlanSucceeds as exc:
            ranking_note, ranking_hint = exc.message, exc.hint
    say("loading trials")
    records = store.visible_trials(branch)
    changes = store.visible_changes(branch)
    outcomes = outcome_matrix(records)
    frequencies = dict(zip(OUTCOME_NAMES, (outcomes.mean(axis=0) if len(records) else np.zeros(6)).round(4).tolist()))
    evaluations: tuple[EvaluationReport, ...] = ()
    note = None
    try:
        done = []
        for index, name in enumerate(models):
            say(f"held-out evaluation of {name}", index, len(models))
            done.append(
                evaluate(name, records, seed=seed, test_fraction=test_fraction, model_seed=fit_seed, changes=changes)
            )
        evaluations = tuple(done)
    except LlcpsError as exc:
        note = exc.message
    rankings: dict[str, dict[str, list[RankedCandidate]]] = {}
    if failure is not None:
        for index, name in enumerate(models):
            say(f"ranking {len(failure.candidates)} candidates with {name}", index, len(models))
            model = fit_or_load(store, branch, name, fit_seed, records=records, changes=changes)
            rankings[name] = {
                measure: top_candidates(model, failure, measure=measure, top=top, seed=seed) for measure in MEASURES
            }
    return ModelInspection(
        branch=branch,
        seed=seed,
        n_trials=len(records),
        label_frequencies=frequencies,
        evaluations=evaluations,
        failure=failure,
        rankings=rankings,
        evaluation_note=note,
        n_changes=len(changes),
        variant=variant if scenario is not None else 0,
        ranking_note=ranking_note,
        ranking_hint=ranking_hint,
    )
