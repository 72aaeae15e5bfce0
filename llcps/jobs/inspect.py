"""``llcps inspect``: what the store holds — trials, runs, episodes, the knowledge base and
how well the world models predict."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from llcps.errors import LlcpsError
from llcps.outputs import write_text
from llcps.jobs._common import Progress, StoreRef, opened

if TYPE_CHECKING:
    from llcps.cps.inspection import ModelInspection
    from llcps.trial_records import TrialRecord
    from llcps.store import EpisodeRecord, OperatorRecord, RunRecord
    from llcps.store.runs import RunComparison


def _scenario_name(scenario: str | None) -> str | None:
    """A scenario filter as its registered name (an alias or a file resolves to it)."""
    if scenario is None:
        return None
    from llcps.scenarios import get_scenario

    return get_scenario(scenario).name


@dataclass(frozen=True)
class TrialsResult:
    """The trials a branch sees, oldest of the selection first."""

    branch: str
    trials: tuple[TrialRecord, ...]


@dataclass(frozen=True)
class RunRow:
    """A run, how long it took and what it wrote (its episodes and its trials by source)."""

    run: RunRecord
    seconds: float | None
    activity: Mapping[str, int]

    def as_json(self) -> dict[str, Any]:
        return {**self.run.as_json(), "seconds": self.seconds, "activity": dict(self.activity)}


@dataclass(frozen=True)
class RunsResult:
    """Runs, oldest first; ``branch`` None means every branch."""

    branch: str | None
    runs: tuple[RunRow, ...]


@dataclass(frozen=True)
class EpisodesResult:
    """Episodes, oldest first; ``branch`` None means every branch."""

    branch: str | None
    episodes: tuple[EpisodeRecord, ...]


@dataclass(frozen=True)
class OperatorCost:
    """An operator of the knowledge base: its executions as plan steps and its plan cost."""

    operator: str
    learned: bool
    successes: int
    failures: int
    nominal_cost: float
    cost: float

    def as_json(self) -> dict[str, Any]:
        return {
            "operator": self.operator,
            "learned": self.learned,
            "successes": self.successes,
            "failures": self.failures,
            "nominal_cost": self.nominal_cost,
            "cost": self.cost,
        }


@dataclass(frozen=True)
class KnowledgeResult:
    """A branch's knowledge base K': its PDDL domain, each operator's cost, the learned operators."""

    branch: str
    domain: str
    operators: tuple[OperatorCost, ...]
    learned_operators: tuple[OperatorRecord, ...]

    def as_json(self) -> dict[str, Any]:
        return {
            "branch": self.branch,
            "domain": self.domain,
            "operators": [op.as_json() for op in self.operators],
            "learned_operators": [op.as_json() for op in self.learned_operators],
        }


def list_trials(
    *,
    store: StoreRef,
    branch: str | None = None,
    scenario: str | None = None,
    source: str | None = None,
    solved: bool | None = None,
    episode: int | None = None,
    limit: int | None = None,
) -> TrialsResult:
    """The trials ``branch`` (None: the current branch) sees that match the filters: the newest
    ``limit`` (None: all), oldest first. ``scenario`` may be a name or its alias."""
    scenario = _scenario_name(scenario)
    with opened(store) as s:
        name = s.resolve_branch(branch).name
        records = s.visible_trials(
            name, source=source, scenario=scenario, solved=solved, episode=episode, limit=limit, newest_first=True
        )
    records.reverse()
    return TrialsResult(branch=name, trials=tuple(records))


def list_runs(
    *, store: StoreRef, branch: str | None = None, all_branches: bool = False, limit: int | None = None, activity: bool = True
) -> RunsResult:
    """The newest ``limit`` (None: all) runs on ``branch`` (None: the current branch; every
    branch with ``all_branches``), oldest first, each with its duration and (with ``activity``)
    its episodes and trials by source."""
    from llcps.store.runs import run_seconds

    with opened(store) as s:
        name = None if all_branches else s.resolve_branch(branch).name
        runs = s.list_runs(branch=name, limit=limit)
        counts = s.run_activity([r.id for r in runs]) if activity else {}
    runs.reverse()
    return RunsResult(branch=name, runs=tuple(RunRow(run=r, seconds=run_seconds(r), activity=counts.get(r.id, {})) for r in runs))


def compare_runs(*, store: StoreRef, a: int, b: int) -> RunComparison:
    """Runs ``a`` and ``b`` side by side, field by field."""
    from llcps.store.runs import compare_runs as compare

    with opened(store) as s:
        return compare(s, a, b)


def list_episodes(
    *,
    store: StoreRef,
    branch: str | None = None,
    all_branches: bool = False,
    scenario: str | None = None,
    run: int | None = None,
    limit: int | None = None,
) -> EpisodesResult:
    """The newest ``limit`` (None: all) episodes run on ``branch`` (None: the current branch;
    every branch with ``all_branches``), oldest first; ``scenario`` may be a name or its alias."""
    scenario = _scenario_name(scenario)
    with opened(store) as s:
        name = None if all_branches else s.resolve_branch(branch).name
        episodes = s.list_episodes(branch=name, scenario=scenario, run_id=run, limit=limit)
    episodes.reverse()
    return EpisodesResult(branch=name, episodes=tuple(episodes))


def knowledge(*, store: StoreRef, branch: str | None = None) -> KnowledgeResult:
    """The knowledge base K' ``branch`` (None: the current branch) plans with, and what its
    experience says of each operator (docs/knowledge.md)."""
    from llcps.cps.branch_knowledge import load_knowledge

    with opened(store) as s:
        name = s.resolve_branch(branch).name
        kb = load_knowledge(s, name)
        learned_operators = s.visible_operators(name)
    learned = {op.name for op in kb.learned}
    operators = tuple(
        OperatorCost(
            operator=op.name,
            learned=op.name in learned,
            successes=kb.counts(op.name)[0],
            failures=kb.counts(op.name)[1],
            nominal_cost=kb.nominal_cost(op.name),
            cost=round(kb.cost(op.name), 4),
        )
        for op in kb.operators()
    )
    return KnowledgeResult(branch=name, domain=kb.to_pddl(), operators=operators, learned_operators=tuple(learned_operators))


#: What ``llcps inspect knowledge --pddl`` writes: K's domain, or a scenario's task for it.
PDDL_PARTS: tuple[str, ...] = ("domain", "problem")

#: How the PDDL export writes costs (:data:`llcps.symbolic.export.COSTS`, kept here so the
#: CLI does not load the PDDL library to list them).
PDDL_COSTS: tuple[str, ...] = ("integer", "none")


@dataclass(frozen=True)
class PddlExport:
    """A plain PDDL file of a branch's K' (``part`` domain) or of a scenario's task for it
    (``part`` problem), and where it was written (None: nowhere)."""

    branch: str
    part: str
    scenario: str | None
    condition: str | None
    variant: int
    costs: str
    text: str
    path: Path | None

    def as_json(self) -> dict[str, Any]:
        return {
            "branch": self.branch,
            "part": self.part,
            "scenario": self.scenario,
            "condition": self.condition,
            "variant": self.variant,
            "costs": self.costs,
            "path": None if self.path is None else str(self.path),
            "pddl": self.text,
        }


def export_pddl(
    *,
    store: StoreRef,
    part: str,
    branch: str | None = None,
    scenario: str | None = None,
    condition: str = "novelty",
    variant: int = 0,
    costs: str = "integer",
    out: str | Path | None = None,
) -> PddlExport:
    """Write the knowledge base K' ``branch`` (None: the current branch) plans with as a plain
    PDDL domain (``part="domain"``), or ``scenario``'s task in ``condition`` as a problem for
    it (``part="problem"``), for other planners: integer costs (experience costs x 1000) or
    none, learned operators' inequalities and context bans as preconditions, and what PDDL
    cannot say in a comment (docs/knowledge.md). Writes ``out`` when given.

    Raises:
        LlcpsError: an unknown part, cost compilation, scenario or condition; a problem
            without a scenario; an unwritable ``out``. Checked before the store opens.
    """
    from llcps.cps.branch_knowledge import load_knowledge
    from llcps.outputs import check_output_file
    from llcps.scenarios import CONDITIONS, get_scenario
    from llcps.scenarios.variants import check_variant
    from llcps.symbolic.export import export_domain, export_problem

    if part not in PDDL_PARTS:
        raise LlcpsError(f"unknown PDDL part {part!r}", hint=f"choose one of: {', '.join(PDDL_PARTS)}")
    if costs not in PDDL_COSTS:
        raise LlcpsError(f"unknown cost compilation {costs!r}", hint=f"choose one of: {', '.join(PDDL_COSTS)}")
    if condition not in CONDITIONS:
        raise LlcpsError(f"unknown condition {condition!r}", hint=f"choose one of: {', '.join(CONDITIONS)}")
    check_variant(variant)
    if part == "problem" and scenario is None:
        raise LlcpsError("a PDDL problem needs a scenario", hint="e.g. `llcps inspect knowledge --pddl problem --scenario scenario2`")
    spec = get_scenario(scenario) if scenario is not None else None
    path = check_output_file(out, what="--out") if out is not None else None
    with opened(store) as s:
        name = s.resolve_branch(branch).name
        kb = load_knowledge(s, name)
    if part == "domain":
        text = export_domain(kb, costs=costs)
    else:
        from llcps.cps.scene_task import perceived_task  # the simulator loads only for a problem

        assert spec is not None
        text = export_problem(kb, perceived_task(spec, condition=condition, variant=variant), costs=costs)
    if path is not None:
        write_text(path, text, what="--out")
    return PddlExport(
        branch=name,
        part=part,
        scenario=None if spec is None else spec.name,
        condition=condition if part == "problem" else None,
        variant=variant,
        costs=costs,
        text=text,
        path=path,
    )


def inspect_model(
    *,
    store: StoreRef,
    branch: str | None = None,
    models: Sequence[str] | None = None,
    scenario: str | None = None,
    variant: int = 0,
    limit: int = 5,
    seed: int = 0,
    model_seed: int | None = None,
    test_fraction: float = 0.25,
    reach_check: bool = True,
    progress: Progress | None = None,
) -> ModelInspection:
    """Evaluate ``models`` (default: the paper's nb and nn) on the trials ``branch`` (None: the
    current branch) sees, on a held-out split, next to the majority baseline; with ``scenario``
    (and its ``variant``), also rank its failure-state candidates under every measure (``limit``
    per measure), those the arm would refuse last unless ``reach_check`` is off."""
    from llcps.models import PAPER_MODELS

    names = list(models) if models else list(PAPER_MODELS)
    if variant and scenario is None:
        raise LlcpsError("--variant needs --scenario", hint="e.g. `llcps inspect model --scenario scenario3 --variant 7`")
    _scenario_name(scenario)  # an unknown name or a bad file fails here, before the store opens; a file is read again by path
    from llcps.cps.inspection import inspect_models  # sklearn loads only when used

    with opened(store) as s:
        name = s.resolve_branch(branch).name
        return inspect_models(
            s,
            branch=name,
            models=names,
            seed=seed,
            model_seed=model_seed,
            test_fraction=test_fraction,
            scenario=scenario,
            top=limit,
            variant=variant,
            reach_check=reach_check,
            progress=progress,
        )
