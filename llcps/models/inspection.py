"""What ``llcps inspect model`` shows: held-out metrics next to the majority baseline,
the training set's label frequencies, and optionally the top candidates of a
scenario's failure state under each measure.

The failure state is reached the way the agent reaches it: the scenario's novelty
condition is built, the branch's knowledge base plans, and the plan runs under the
monitor until its first failing step. Nothing is written to the store on the way
(except the fitted models, stored by :func:`~llcps.models.persistence.fit_or_load`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from llcps.domain import OUTCOME_NAMES, WorldModelInput
from llcps.errors import LlcpsError
from llcps.models.base import WorldModel
from llcps.models.evaluation import EvaluationReport, evaluate
from llcps.models.features import outcome_matrix
from llcps.models.measures import MEASURES, get_measure, rank
from llcps.models.persistence import fit_or_load
from llcps.models.registry import world_model_entry

if TYPE_CHECKING:
    from llcps.store import Store


@dataclass(frozen=True)
class RankedCandidate:
    """One candidate trial in a measure's order, with the prediction it was ranked by."""

    position: int
    trial: str
    score: float
    outcome: dict[str, float]


@dataclass(frozen=True)
class FailurePoint:
    """A scenario's failure state: what failed, the wish, and the candidate trials."""

    scenario: str
    failed_action: str
    missing_effects: str
    desired: np.ndarray
    candidates: tuple[WorldModelInput, ...]


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

    def as_json(self) -> dict[str, Any]:
        data: dict[str, Any] = {
            "branch": self.branch,
            "seed": self.seed,
            "n_trials": self.n_trials,
            "label_frequencies": self.label_frequencies,
            "evaluations": [report.as_json() for report in self.evaluations],
            "evaluation_note": self.evaluation_note,
        }
        if self.failure is not None:
            data["scenario"] = {
                "name": self.failure.scenario,
                "failed_action": self.failure.failed_action,
                "missing_effects": self.failure.missing_effects,
                "desired": dict(zip(OUTCOME_NAMES, self.failure.desired.round(4).tolist())),
                "candidates": len(self.failure.candidates),
                "rankings": {
                    model: {measure: [asdict(c) for c in ranked] for measure, ranked in by_measure.items()}
                    for model, by_measure in self.rankings.items()
                },
            }
        return data


def top_candidates(
    model: WorldModel,
    candidates: Sequence[WorldModelInput],
    *,
    measure: str,
    top: int,
    seed: int,
    desired: np.ndarray | None = None,
) -> list[RankedCandidate]:
    """The ``top`` best candidates under ``measure`` with their predicted Omega."""
    proba = model.predict_proba(candidates)
    order = rank(proba, measure, seed=seed, desired=desired)[:top]
    score = get_measure(measure).score(proba, desired)
    return [
        RankedCandidate(
            position=position + 1,
            trial=candidates[i].spec.label,
            score=round(float(score[i]), 6),
            outcome={name: round(float(p), 4) for name, p in zip(OUTCOME_NAMES, proba[i])},
        )
        for position, i in enumerate(order)
    ]


def failure_point(store: Store, *, branch: str, scenario: str, seed: int) -> FailurePoint:
    """Run ``scenario``'s novelty plan (nothing stored) to its first failure.

    Raises:
        LlcpsError: unknown scenario, no plan, or a plan that does not fail.
    """
    # The agent's machinery (PyBullet, planner) loads only when a scenario is asked for.
    from llcps.cps.agent import SETTLE_STEPS, Agent, SolveConfig, SolveResult, load_knowledge
    from llcps.cps.candidates import enumerate_candidates
    from llcps.cps.outcomes import desired_outcome
    from llcps.sim.perception import entity_features, perceive
    from llcps.sim.world import World
    from llcps.symbolic.planner import plan

    config = SolveConfig(scenario=scenario, seed=seed)
    spec = config.validate()
    world = World.from_scene(spec.scene("novelty"))
    try:
        world.settle(max_steps=SETTLE_STEPS)
        result = SolveResult(
            scenario=spec.name, condition="novelty", model="-", measure="-", seed=seed, branch=branch
        )
        agent = Agent(
            store=store, branch=branch, world=world, scenario=spec, config=config, result=result, records=[]
        )
        kb = load_knowledge(store, branch)
        steps = plan(kb, agent.task(perceive(world)))
        if not steps:
            raise LlcpsError(f"the knowledge base of {branch!r} has no plan for {spec.name}'s novelty condition")
        run = agent.run_plan(steps, store=False)
        if run.failure is None:
            learned = bool(store.visible_operators(branch))
            raise LlcpsError(
                f"the plan for {spec.name}'s novelty condition succeeds on {branch!r}: no failure state to rank",
                hint="the branch has learned operators that resolve it; inspect a branch that has not"
                if learned
                else "the novelty does not make the nominal plan fail (see docs/scenarios.md)",
            )
        failed_step, failure = run.failure.step, run.failure.monitor
        world.restore_serialized(run.failure.physics)  # candidates start where a_f did
        failed_spec = agent.controller_call(failed_step)
        specs = enumerate_candidates(failed=failed_spec, entities=agent.kinds, grid=config.candidate_grid(spec))
        features = {name: entity_features(world, name) for name in agent.kinds}
        candidates = tuple(WorldModelInput(spec=c, features=tuple(features[a] for a in c.arguments)) for c in specs)
        desired = desired_outcome(missing_add=failure.missing_add, missing_del=failure.missing_del)
    finally:
        world.close()
    return FailurePoint(
        scenario=spec.name,
        failed_action=failed_step.label,
        missing_effects=failure.describe(),
        desired=desired,
        candidates=candidates,
    )


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
    progress: Callable[[str, int, int], None] | None = None,
) -> ModelInspection:
    """Evaluate ``models`` on the branch's trials and, with a scenario, rank its candidates.

    Args:
        store: the experience store.
        branch: whose visible trials train and test the models.
        models: WORLD_MODELS names.
        seed: seeds the held-out split and tie-breaks (and the models, without ``model_seed``).
        test_fraction: share of trials held out for the metrics.
        scenario: a scenario whose failure state's candidates to rank (optional).
        top: candidates shown per measure.
        model_seed: seed of the world models (None: ``seed``).
        progress: called as ``progress(phase, done, total)`` as the work goes on.
    """
    fit_seed = seed if model_seed is None else model_seed

    def say(phase: str, done: int = 0, total: int = 0) -> None:
        if progress is not None:
            progress(phase, done, total)

    for name in models:
        world_model_entry(name)
    if top < 1:
        raise LlcpsError(f"--top must be at least 1, got {top}")
    say("loading trials")
    records = store.visible_trials(branch)
    outcomes = outcome_matrix(records)
    frequencies = dict(zip(OUTCOME_NAMES, (outcomes.mean(axis=0) if len(records) else np.zeros(6)).round(4).tolist()))
    evaluations: tuple[EvaluationReport, ...] = ()
    note = None
    try:
        done = []
        for index, name in enumerate(models):
            say(f"held-out evaluation of {name}", index, len(models))
            done.append(evaluate(name, records, seed=seed, test_fraction=test_fraction, model_seed=fit_seed))
        evaluations = tuple(done)
    except LlcpsError as exc:
        note = exc.message
    failure = None
    rankings: dict[str, dict[str, list[RankedCandidate]]] = {}
    if scenario is not None:
        say(f"{scenario}: running the plan to its failure")
        failure = failure_point(store, branch=branch, scenario=scenario, seed=seed)
        for index, name in enumerate(models):
            say(f"ranking {len(failure.candidates)} candidates with {name}", index, len(models))
            model = fit_or_load(store, branch, name, fit_seed, records=records)
            rankings[name] = {
                measure: top_candidates(
                    model, failure.candidates, measure=measure, top=top, seed=seed, desired=failure.desired
                )
                for measure in MEASURES
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
    )
