"""What a report needs from the store beyond the results table: where the runs ran
(provenance) and a film of a resolving trial per scenario.

Both are written into the report directory (``provenance.json``, ``films/``), so a
report rebuilt later from that directory alone still shows them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from llcps.analysis.results import ResultsTable
from llcps.cps.film import episode_shots, reenact
from llcps.experiments.design import scenario_rank
from llcps.experiments.rows import ResultRow
from llcps.outputs import write_text
from llcps.errors import LlcpsError
from llcps.inputs import read_user_text
from llcps.limits import MAX_RESULTS_FILE_BYTES
from llcps.provenance import Provenance
from llcps.store import Store

PROVENANCE_FILE = "provenance.json"
FILMS_DIR = "films"


def table_provenance(store: Store, table: ResultsTable) -> list[dict[str, Any]]:
    """The distinct environments the table's episodes ran in, with how many runs each."""
    wanted = {r.episode_id for r in table if r.episode_id is not None}
    run_ids = {e.run_id for e in store.list_episodes() if e.id in wanted and e.run_id is not None}
    counts: dict[Provenance, int] = {}
    for run in store.list_runs(ids=sorted(run_ids)):
        counts[run.provenance] = counts.get(run.provenance, 0) + 1
    ordered = sorted(counts.items(), key=lambda kv: (-kv[1], json.dumps(kv[0].as_json(), sort_keys=True, default=str)))
    return [{**env.as_json(), "runs": n} for env, n in ordered]


def write_provenance(out_dir: Path, provenance: Sequence[Mapping[str, Any]]) -> Path:
    path = out_dir / PROVENANCE_FILE
    return write_text(path, json.dumps(list(provenance), indent=1, sort_keys=True) + "\n", what="report")


#: The key marking which results directory an environment's runs came from, in a report of several.
RESULTS_KEY = "results"


def read_provenance(out_dir: Path) -> list[dict[str, Any]]:
    """The provenance a report directory holds; empty when it has none or it is unreadable."""
    path = out_dir / PROVENANCE_FILE
    if not path.exists():
        return []
    try:
        data = json.loads(read_user_text(path, what="provenance file", max_bytes=MAX_RESULTS_FILE_BYTES, hint=""))
    except (LlcpsError, ValueError, RecursionError):
        return []
    known = set(Provenance.__dataclass_fields__) | {"runs", RESULTS_KEY}
    return [{k: v for k, v in item.items() if k in known} for item in data if isinstance(item, dict)] if isinstance(data, list) else []


def merged_provenance(source_dirs: Sequence[Path]) -> list[dict[str, Any]]:
    """The provenance of several results directories, each environment marked with the
    directory it was read from (:data:`RESULTS_KEY`; one marked already keeps its mark).

    Run counts stay per directory: a run whose rows two directories hold (a copied
    store's) is counted in each, so they are not added up.
    """
    merged: list[dict[str, Any]] = []
    for folder in source_dirs:
        for item in read_provenance(Path(folder)):
            marked = {**item, RESULTS_KEY: item.get(RESULTS_KEY) or str(folder)}
            if marked not in merged:
                merged.append(marked)
    return merged


def provenance_line(item: Mapping[str, Any]) -> str:
    """One environment for people, with its run count (and the results directory it came from, if marked)."""
    env = Provenance(**{k: v for k, v in item.items() if k in Provenance.__dataclass_fields__})
    runs = item.get("runs")
    source = item.get(RESULTS_KEY)
    return env.summary() + (f" — {runs} run(s)" if isinstance(runs, int) else "") + (f" [{source}]" if isinstance(source, str) else "")


def typical_resolution(rows: Sequence[ResultRow]) -> ResultRow | None:
    """The solved episode with the median exploration (ties: the lower episode id)."""
    solved = sorted((r for r in rows if r.solved and r.episode_id is not None), key=lambda r: (r.exploration_trials, r.episode_id))
    return solved[len(solved) // 2] if solved else None


def film_resolutions(
    store: Store,
    table: ResultsTable,
    out_dir: Path,
    *,
    progress: Callable[[str, int, int], None] | None = None,
) -> dict[str, Path]:
    """Film, per scenario, the resolving trial of a typical solved episode and the plan it enabled.

    Returns:
        scenario -> GIF path, for the scenarios with a solved episode.
    """
    films: dict[str, Path] = {}
    target = out_dir / FILMS_DIR
    for scenario in sorted(table.unique("scenario"), key=scenario_rank):
        row = typical_resolution([r for r in table if r.scenario == scenario])
        if row is None or row.episode_id is None:
            continue
        shots = episode_shots(store, row.episode_id)
        resolution = [s for s in shots if s.phase in ("explore", "re-plan")] or shots
        target.mkdir(parents=True, exist_ok=True)
        path = target / f"{scenario}.gif"
        report = None if progress is None else (lambda phase, done, total, s=scenario: progress(f"film {s}", done, total))
        reenact(store, resolution, gif=path, progress=report)
        films[scenario] = path
    return films


def existing_films(out_dir: Path) -> dict[str, Path]:
    """The films a report directory already holds, by scenario."""
    folder = out_dir / FILMS_DIR
    return {p.stem: p for p in sorted(folder.glob("*.gif"), key=lambda p: scenario_rank(p.stem))}


__all__ = [
    "FILMS_DIR",
    "PROVENANCE_FILE",
    "RESULTS_KEY",
    "existing_films",
    "film_resolutions",
    "merged_provenance",
    "provenance_line",
    "read_provenance",
    "table_provenance",
    "typical_resolution",
    "write_provenance",
]
