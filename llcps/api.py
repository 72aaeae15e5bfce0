"""The Python API for analysis and for the main jobs: ``llcps.open(...)`` returns a
:class:`Workbench` over one experience store.

Reads return pandas DataFrames with tidy, typed columns: :meth:`Workbench.trials`
has one row per trial and one column per Table-1 feature per argument slot, per
outcome bit and per further column source (:mod:`llcps.store.flat`); episodes, runs
(with their provenance) and learned operators have their own frames. The jobs the
CLI runs (pretrain, solve, replay, an experiment grid) are methods too, returning
the same result objects the CLI prints. Nothing here imports typer or rich; pandas
loads when this module does, and ``import llcps`` does not load this module.

    import llcps
    wb = llcps.open("llcps.db")
    trials = wb.trials(source="exploration")
    trials.groupby("scenario").size()
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from llcps.cps.episode import SolveConfig, SolveResult
from llcps.cps.orderings.base import resolving_pick
from llcps.errors import LlcpsError
from llcps.jobs.solve import solve as solve_job
from llcps.provenance import FIELDS as PROVENANCE_FIELDS
from llcps.store import Store
from llcps.domain import ACTIONS, COLORS, ENTITY_NUMBERS, ORIENTATIONS, OUTCOME_NAMES, SHAPES, TRIAL_SOURCES
from llcps.store import trial_blocks
from llcps.store.flat import ARGUMENT_SLOTS, ENTITY_FIELDS, KINDS, TRIAL_COLUMN_SOURCES, Column, flat_rows, trial_columns
from llcps.store.trial_blocks import TrialColumns

if TYPE_CHECKING:
    from llcps.cps.replay import ReplayReport
    from llcps.experiments.scheduler import RunSummary
    from llcps.jobs.experiment import ExperimentReport
    from llcps.jobs.life import LifeRun
    from llcps.models.persistence import FittedModel
    from llcps.cps.pretraining import PretrainSummary

#: Columns of :meth:`Workbench.episodes`: name -> (kind, meaning); kinds are keys of llcps.store.flat.KINDS.
EPISODE_COLUMNS: Mapping[str, tuple[str, str]] = {
    "id": ("int", "episode id"),
    "run_id": ("nullable_int", "the run it belongs to"),
    "branch": ("string", "the branch it ran on"),
    "scenario": ("string", "scenario name"),
    "condition": ("string", "original or novelty"),
    "model": ("string", "world model that ranked exploration"),
    "measure": ("string", "measure that ordered candidates"),
    "seed": ("nullable_int", "the episode's seed"),
    "status": ("string", "solved, budget_exhausted, no_plan, interrupted, error or running"),
    "solved": ("bool", "status is solved"),
    "exploration_trials": ("nullable_int", "exploration trials the episode made"),
    "plan_trials": ("nullable_int", "plan trials the episode made"),
    "candidates": ("nullable_int", "size of the candidate space at the failure"),
    "sim_seconds": ("float", "simulated seconds"),
    "wall_seconds": ("float", "wall seconds (rendering excluded)"),
    "failed_action": ("string", "the plan step that failed"),
    "resolving_trial_id": ("nullable_int", "the exploration trial that resolved the novelty"),
    "learned_operators": ("nullable_int", "operators learned"),
    "started_at": ("timestamp", "start (UTC)"),
    "finished_at": ("timestamp", "end (UTC)"),
    "variant": ("nullable_int", "the scene variant"),
    "life_name": ("string", "the life file of a `life run` episode (else empty)"),
    "life": ("nullable_int", "its life number (the seed of the life's draws)"),
    "life_condition": ("string", "the condition its life ran under (update, reset, scratch, random)"),
    "life_episode": ("nullable_int", "its index in the life (empty for a re-solve after the life)"),
    "first_encounter": ("nullable_bool", "the first episode of its family in the life"),
    "ordering": ("string", "the exploration ordering it ran (ranked, hedged, ...)"),
    "resolving_pick": ("string", "the side of the ordering that chose the resolving trial (the hedge's model or random; else empty)"),
}

#: Columns of :meth:`Workbench.lives` (``episodes.csv`` of ``life run``): name -> (kind, meaning).
LIFE_COLUMNS: Mapping[str, tuple[str, str]] = {
    "life": ("int", "the life's number (the seed of its draws)"),
    "condition": ("string", "update, reset, scratch or random"),
    "episode": ("int", "index in the life; -1 for a re-solve after it"),
    "family": ("string", "the novelty family (scenario)"),
    "variant": ("int", "the scene variant"),
    "first_encounter": ("bool", "the family's first episode in the life"),
    "probe": ("bool", "a probe family (held back to the last quarter)"),
    "episode_condition": ("string", "novelty or original"),
    "exploration_trials": ("int", "exploration trials the episode made"),
    "solved": ("bool", "the novelty was resolved"),
    "censored": ("bool", "not solved: its count is censored at tau"),
    "wall_seconds": ("float", "wall seconds"),
    "sim_seconds": ("float", "simulated seconds"),
    "tau": ("int", "the AUC's horizon"),
    "phase": ("string", "life, or after (the forgetting re-solves)"),
    "status": ("string", "the episode's status"),
}

#: Columns of :meth:`Workbench.runs`.
RUN_COLUMNS: Mapping[str, tuple[str, str]] = {
    "id": ("int", "run id"),
    "command": ("string", "the command that ran"),
    "branch": ("string", "the branch it ran on"),
    "seed": ("nullable_int", "the run seed"),
    "status": ("string", "how it ended"),
    "started_at": ("timestamp", "start (UTC)"),
    "finished_at": ("timestamp", "end (UTC)"),
    "config": ("string", "its configuration, as JSON"),
    "llcps_version": ("string", "llcps version"),
    "git_commit": ("string", "commit of llcps's source tree, if any"),
    "git_dirty": ("nullable_bool", "the tree had uncommitted changes"),
    "python_version": ("string", "Python version"),
    "pybullet_version": ("string", "PyBullet version"),
    "torch_version": ("string", "torch version"),
    "sklearn_version": ("string", "scikit-learn version"),
    "numpy_version": ("string", "numpy version"),
    "host": ("string", "host name"),
    "cpu_count": ("nullable_int", "CPUs available to it"),
}

#: Columns of :meth:`Workbench.operators`.
OPERATOR_COLUMNS: Mapping[str, tuple[str, str]] = {
    "id": ("int", "operator id"),
    "branch": ("string", "the branch that learned it"),
    "name": ("string", "operator name"),
    "scenario": ("string", "the scenario it was learned in"),
    "episode_id": ("nullable_int", "the episode that learned it"),
    "watermark": ("int", "the largest trial id visible when it was learned"),
    "created_at": ("timestamp", "when (UTC)"),
    "pddl": ("string", "the operator in PDDL"),
}

def _convert(series: pd.Series, kind: str, categories: Sequence[str] = ()) -> pd.Series:
    """One column to its documented dtype (values read from the database are untrusted)."""
    if kind == "category":
        seen = [v for v in dict.fromkeys(series.dropna()) if v not in categories]
        return series.astype(pd.CategoricalDtype([*categories, *sorted(map(str, seen))]))
    if kind == "timestamp":
        return pd.to_datetime(series, format="ISO8601", errors="coerce").astype("datetime64[ns]")
    if kind in ("float",):
        return pd.to_numeric(series, errors="coerce").astype("float64")
    if kind == "bool":
        return series.fillna(False).astype(bool)
    return series.astype(KINDS[kind])


def _frame(rows: list[dict[str, Any]], columns: Iterable[tuple[str, str, Sequence[str]]]) -> pd.DataFrame:
    spec = list(columns)
    frame = pd.DataFrame.from_records(rows, columns=[name for name, _, _ in spec])
    for name, kind, categories in spec:
        frame[name] = _convert(frame[name], kind, categories)
    return frame


def _life_place(place: Any) -> dict[str, Any]:
    """The life columns of an episode from its summary's ``life`` entry (untrusted)."""
    if not isinstance(place, Mapping):
        return {"life_name": None, "life": None, "life_condition": None, "life_episode": None, "first_encounter": None}
    name, condition, first = place.get("name"), place.get("condition"), place.get("first_encounter")
    return {
        "life_name": name if isinstance(name, str) else None,
        "life": _number(place.get("life")),
        "life_condition": condition if isinstance(condition, str) else None,
        "life_episode": _number(place.get("episode")),
        "first_encounter": first if isinstance(first, bool) else None,
    }


def trial_frame(store: Store, records: Sequence[Any]) -> pd.DataFrame:
    """Trials as the tidy DataFrame of :meth:`Workbench.trials`."""
    columns: Sequence[Column] = trial_columns()
    return _frame(flat_rows(store, records), ((c.name, c.kind, c.categories) for c in columns))


def columns_frame(columns: TrialColumns) -> pd.DataFrame:
    """Trials read as columns (:meth:`Store.visible_columns`) as the tidy DataFrame of
    :meth:`Workbench.trials`: the frame :func:`trial_frame` makes of the same trials' records,
    built from arrays instead of one row per trial."""
    branch_ids = np.array(sorted(dict(columns.branch_names)), dtype=np.int64)
    branch_names = [dict(columns.branch_names)[b] for b in branch_ids.tolist()]

    def objects(values: Sequence[Any], codes: np.ndarray) -> np.ndarray:
        """The value of each code (None for a code of -1), as an object array."""
        table = np.empty(len(values) + 1, dtype=object)
        table[: len(values)] = list(values)
        return table[codes]

    def category(values: Sequence[str], codes: np.ndarray, known: Sequence[str]) -> pd.Categorical:
        categories = [*known, *sorted(set(values) - set(known))]
        index = np.array([categories.index(v) for v in values] + [-1], dtype=np.int64)
        return pd.Categorical.from_codes(index[codes], categories=pd.CategoricalDtype(categories).categories)

    def nullable(values: np.ndarray) -> pd.arrays.IntegerArray:
        return pd.arrays.IntegerArray(values.astype(np.int64), values == trial_blocks.NONE)

    data: dict[str, Any] = {
        "id": columns.id.astype(np.int64),
        "branch": objects(branch_names, np.searchsorted(branch_ids, columns.branch_id)),
        "run_id": nullable(columns.run_id),
        "episode_id": nullable(columns.episode_id),
        "scenario": objects(columns.scenarios, columns.scenario),
        "source": category(columns.sources, columns.source, TRIAL_SOURCES),
        "action": category(columns.actions, columns.action, ACTIONS),
        "rate": columns.rate.astype(np.float64),
        "movement_magnitude": columns.movement_magnitude.astype(np.float64),
        "orientation": category(columns.orientations, columns.orientation, ORIENTATIONS),
    }
    for slot in range(ARGUMENT_SLOTS):
        names = [a[slot] if slot < len(a) else None for a in columns.argument_lists]
        data[f"arg{slot}"] = objects(names, columns.arguments)
        for name in ENTITY_FIELDS:
            if name == "shape":
                data[f"arg{slot}_shape"] = category(SHAPES, columns.shape[:, slot].astype(np.int64), SHAPES)
            elif name == "color":
                data[f"arg{slot}_color"] = category(COLORS, columns.color[:, slot].astype(np.int64), COLORS)
            else:
                data[f"arg{slot}_{name}"] = columns.numbers[:, slot, ENTITY_NUMBERS.index(name)].astype(np.float64)
    for bit, name in enumerate(OUTCOME_NAMES):
        data[name] = columns.bit(bit)
    data["solved"] = columns.bit(trial_blocks.SOLVED_BIT)
    data["sim_steps"] = columns.sim_steps.astype(np.int64)
    data["wall_seconds"] = columns.wall_seconds.astype(np.float64)
    data["seed"] = columns.seed.astype(np.int64)
    data["snapshot_id"] = nullable(columns.snapshot_id)
    stamps = columns.created_at.astype(np.int64)
    data["created_at"] = np.where(stamps == trial_blocks.NO_TIME, np.datetime64("NaT"), stamps.astype("datetime64[us]")).astype("datetime64[ns]")
    frame = pd.DataFrame(data)
    for column in trial_columns():
        if column.kind == "string":
            frame[column.name] = frame[column.name].astype("string")
    return frame[[c.name for c in trial_columns()]]


def _number(value: Any) -> Any:
    """A summary value that must be a number (anything else read from the database is dropped)."""
    return value if isinstance(value, (int, float)) and not isinstance(value, bool) else None


class Workbench:
    """One experience store, for analysis in pandas and for running the main jobs.

    Open it with :func:`llcps.open`; close it (or use ``with``) when done.
    """

    def __init__(self, store: Store) -> None:
        self.store = store

    @classmethod
    def open(cls, url_or_path: str | Path = "llcps.db", *, create: bool = False) -> Workbench:
        """Open a store by SQLite path or SQLAlchemy URL (see :meth:`llcps.store.Store.open`)."""
        return cls(Store.open(str(url_or_path), create=create))

    def close(self) -> None:
        self.store.close()

    def __enter__(self) -> Workbench:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Workbench({self.store.url!r})"

    # ------------------------------------------------------------------ reads

    def trials(
        self,
        *,
        branch: str | None = None,
        source: str | None = None,
        scenario: str | None = None,
        episode: int | None = None,
        solved: bool | None = None,
    ) -> pd.DataFrame:
        """The trials ``branch`` sees (default: the current branch), oldest first, one row each.

        The columns are those of ``llcps db export`` (:func:`llcps.store.flat.trial_columns`):
        ids, the controller call, ``arg<k>_<feature>`` per argument slot, the six outcome
        bits and ``solved`` as booleans, and what the store records.
        """
        if len(TRIAL_COLUMN_SOURCES) > 1:  # a registered source computes its columns from records
            records = self.store.visible_trials(branch, source=source, scenario=scenario, episode=episode, solved=solved)
            return trial_frame(self.store, records)
        columns = self.store.visible_columns(branch, source=source, scenario=scenario, episode=episode, solved=solved)
        return columns_frame(columns)

    def episodes(
        self, *, branch: str | None = None, scenario: str | None = None, run: int | None = None
    ) -> pd.DataFrame:
        """Episodes (scenario solves), oldest first; ``branch`` None means every branch."""
        rows = []
        for e in reversed(self.store.list_episodes(branch=branch, scenario=scenario, run_id=run)):
            summary = e.summary
            operators = summary.get("learned_operators")
            rows.append(
                {
                    "id": e.id,
                    "run_id": e.run_id,
                    "branch": e.branch,
                    "scenario": e.scenario,
                    "condition": e.condition,
                    "model": e.model,
                    "measure": e.measure,
                    "seed": e.seed,
                    "status": e.status,
                    "solved": e.status == "solved",
                    **{k: _number(summary.get(k)) for k in ("exploration_trials", "plan_trials", "candidates", "sim_seconds", "wall_seconds", "resolving_trial_id")},
                    "failed_action": summary.get("failed_action") if isinstance(summary.get("failed_action"), str) else None,
                    "learned_operators": len(operators) if isinstance(operators, list) else None,
                    "started_at": e.started_at or None,
                    "finished_at": e.finished_at,
                    "variant": _number(summary.get("variant")),
                    **_life_place(summary.get("life")),
                    "ordering": summary.get("ordering") if isinstance(summary.get("ordering"), str) else None,
                    "resolving_pick": resolving_pick(summary) if e.status == "solved" else None,
                }
            )
        return _frame(rows, ((n, k, ()) for n, (k, _) in EPISODE_COLUMNS.items()))

    def lives(self, life: str = "default") -> pd.DataFrame:
        """Every stored episode of a life file (a shipped name or a path): one row per
        (life, condition, episode), the columns of ``episodes.csv`` (:data:`LIFE_COLUMNS`),
        and the re-solves after each life (``phase`` ``after``)."""
        from dataclasses import asdict

        from llcps.jobs.life import read_rows, resolve_life

        rows = [asdict(r) for r in read_rows(self.store, resolve_life(life))]
        return _frame(rows, ((n, k, ()) for n, (k, _) in LIFE_COLUMNS.items()))

    def life(
        self,
        life: str = "default",
        *,
        lives: int = 1,
        first_life: int = 0,
        episodes: int | None = None,
        conditions: Iterable[str] | None = None,
        workers: int = 1,
        out_dir: str | Path | None = None,
        html: bool = False,
        progress: Callable[[int, int, str], None] | None = None,
    ) -> LifeRun:
        """``llcps life run``: every (life, condition) not stored yet, then the report in ``out_dir``."""
        from llcps.jobs.life import run_life_job

        return run_life_job(
            store=self.store, life=life, lives=lives, first_life=first_life, episodes=episodes, conditions=conditions,
            workers=workers, out_dir=out_dir, html=html, progress=progress,
        )  # fmt: skip

    def runs(self, *, branch: str | None = None) -> pd.DataFrame:
        """Runs with their provenance, oldest first; ``branch`` None means every branch."""
        rows = []
        for r in reversed(self.store.list_runs(branch=branch)):
            row = {
                "id": r.id,
                "command": r.command,
                "branch": r.branch,
                "seed": r.seed,
                "status": r.status,
                "started_at": r.started_at or None,
                "finished_at": r.finished_at,
                "config": json.dumps(dict(r.config), sort_keys=True, default=str),
            }
            row.update({name: getattr(r.provenance, name) for name in PROVENANCE_FIELDS})
            rows.append(row)
        return _frame(rows, ((n, k, ()) for n, (k, _) in RUN_COLUMNS.items()))

    def operators(self, *, branch: str | None = None) -> pd.DataFrame:
        """The learned operators ``branch`` sees (default: the current branch), oldest first."""
        rows = [
            {
                "id": o.id,
                "branch": o.branch,
                "name": o.name,
                "scenario": o.scenario,
                "episode_id": o.episode_id,
                "watermark": o.watermark,
                "created_at": o.created_at or None,
                "pddl": o.pddl,
            }
            for o in self.store.visible_operators(branch)
        ]
        return _frame(rows, ((n, k, ()) for n, (k, _) in OPERATOR_COLUMNS.items()))

    def pddl(
        self,
        part: str,
        *,
        scenario: str | None = None,
        condition: str = "novelty",
        variant: int = 0,
        costs: str = "integer",
        branch: str | None = None,
        out: str | Path | None = None,
    ) -> str:
        """Plain PDDL of the branch's K' (``part="domain"``) or of ``scenario``'s task for it
        (``part="problem"``), as ``llcps inspect knowledge --pddl`` writes it (docs/knowledge.md)."""
        from llcps.jobs.inspect import export_pddl

        return export_pddl(
            store=self.store, part=part, branch=branch, scenario=scenario, condition=condition, variant=variant, costs=costs, out=out
        ).text

    def compare_runs(self, a: int, b: int) -> pd.DataFrame:
        """Runs ``a`` and ``b`` side by side: one row per field, with whether they agree."""
        from llcps.jobs.inspect import compare_runs

        comparison = compare_runs(store=self.store, a=a, b=b)
        return pd.DataFrame(
            {
                "field": [f.name for f in comparison.fields],
                f"run {a}": [f.a for f in comparison.fields],
                f"run {b}": [f.b for f in comparison.fields],
                "same": [f.same for f in comparison.fields],
            }
        )

    # ------------------------------------------------------------------- jobs

    def pretrain(
        self,
        *,
        trials: int = 200,
        seed: int = 0,
        branch: str | None = None,
        models: Sequence[str] | None = None,
        model_seed: int = 0,
        again: bool = False,
        progress: Callable[[int, int], None] | None = None,
    ) -> tuple[PretrainSummary, list[FittedModel]]:
        """``llcps pretrain``: random interactions stored as trials, then world models fitted.

        A finished pretraining with the same ``trials`` and ``seed`` already on the branch is
        not run again (the summary is that run's) unless ``again``."""
        from llcps.jobs.pretrain import INTERACTIONS, pretrain

        def report(phase: str, done: int = 0, total: int | None = None) -> None:
            if progress is not None and phase == INTERACTIONS:
                progress(done, total or 0)

        result = pretrain(
            store=self.store,
            branch=branch,
            trials=trials,
            seed=seed,
            models=models,
            model_seed=model_seed,
            again=again,
            progress=report,
        )
        return result.summary, list(result.models)

    def solve(
        self,
        scenario: str,
        *,
        branch: str | None = None,
        gif: str | Path | None = None,
        progress: Callable[[str, int, int], None] | None = None,
        **config: Any,
    ) -> SolveResult:
        """``llcps solve``: one episode. ``config`` takes the fields of
        :class:`~llcps.cps.episode.SolveConfig` (condition, model, measure, seed, model_seed, budget, ...)."""
        try:
            SolveConfig(scenario=scenario, **config)
        except TypeError as exc:
            raise LlcpsError(f"bad solve setting: {exc}", hint="see llcps.cps.episode.SolveConfig") from None
        return solve_job(store=self.store, scenario=scenario, branch=branch, gif=gif, progress=progress, **config)

    def replay(self, trial_id: int, *, gif: str | Path | None = None) -> ReplayReport:
        """``llcps replay``: re-execute a stored trial; ``.matches`` says whether it reproduced."""
        from llcps.jobs.replay import replay

        return replay(store=self.store, trial_id=trial_id, gif=gif)

    def experiment(
        self,
        preset: str = "smoke",
        *,
        seeds: int | Iterable[int] | None = None,
        variants: range | None = None,
        scenarios: Iterable[str] | None = None,
        with_others: bool = False,
        workers: int = 1,
        out_dir: str | Path | None = None,
        html: bool = False,
        progress: Callable[[int, int, str], None] | None = None,
    ) -> RunSummary:
        """``llcps experiment run``: every missing sequence of a grid, then its report in ``out_dir``.

        ``variants`` (e.g. ``range(100, 110)``) takes the place of ``seeds``: seed N solves scene variant N.
        ``scenarios`` (names, aliases or .toml paths) replaces the preset's list; ``with_others``
        solves each held-out scenario after the others (``--with-others``).
        """
        from llcps.jobs.experiment import run_experiment_job  # the runner, scipy and matplotlib load here

        return run_experiment_job(
            store=self.store,
            preset=preset,
            seeds=seeds,
            variants=variants,
            scenarios=scenarios,
            with_others=with_others,
            workers=workers,
            out_dir=out_dir,
            html=html,
            progress=progress,
        ).summary

    def experiment_report(
        self,
        preset: str | None = None,
        *,
        baseline_preset: str | None = None,
        variants: range | None = None,
        out_dir: str | Path | None = None,
        html: bool = False,
    ) -> ExperimentReport:
        """``llcps experiment report --from-db``: rebuild a preset's report from the store's episodes
        (default directory ``results/<preset>``); ``.analysis`` holds it as JSON data."""
        from llcps.jobs.experiment import report_experiment_job  # scipy and matplotlib load here

        return report_experiment_job(
            source=self.store, preset=preset, baseline_preset=baseline_preset, variants=variants, out_dir=out_dir, html=html
        )


def open(url_or_path: str | Path = "llcps.db", *, create: bool = False) -> Workbench:  # noqa: A001 - llcps.open
    """A :class:`Workbench` on the store at ``url_or_path`` (a SQLite path or an SQLAlchemy URL)."""
    return Workbench.open(url_or_path, create=create)


__all__ = ["EPISODE_COLUMNS", "LIFE_COLUMNS", "OPERATOR_COLUMNS", "RUN_COLUMNS", "Workbench", "open", "trial_frame"]
