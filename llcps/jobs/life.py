"""Jobs of ``llcps life``: run lives (paired over conditions) and report on them, list
and show the shipped life files.

Running (:func:`llcps.experiments.runner.run_lives`) and reporting
(:mod:`llcps.analysis.lives`, :mod:`llcps.report.lives`) are composed here once, for
the CLI and :mod:`llcps.api` alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

from llcps.analysis.lives import LifeRow, life_metrics, life_rows
from llcps.errors import LlcpsError
from llcps.experiments.life import Life, LifeDraw, condition_names, draw_life, load_life, shipped_lives
from llcps.experiments.life import MAX_LIVES
from llcps.experiments.runner import run_lives
from llcps.experiments.scheduler import ProgressCallback, RunSummary
from llcps.report.lives import LifeReportPaths, write_life_report
from llcps.store import Store


@dataclass(frozen=True)
class LifeRun:
    """What ``life run`` did, and the report it wrote (None when interrupted or empty)."""

    summary: RunSummary
    life: Life
    report: LifeReportPaths | None = None
    metrics: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class LifeReport:
    life: Life
    report: LifeReportPaths
    metrics: Mapping[str, Any]
    rows: int


def default_life_dir(life: str) -> Path:
    return Path("results") / f"life_{life}"


def life_seeds(lives: int, first_life: int = 0) -> tuple[int, ...]:
    """Lives ``first_life .. first_life + lives - 1`` (runners on several machines take disjoint ones)."""
    if isinstance(lives, bool) or not isinstance(lives, int) or not 1 <= lives <= MAX_LIVES:
        raise LlcpsError(f"--lives must be from 1 to {MAX_LIVES}, not {lives!r}", hint="pass --lives 1 or more")
    if isinstance(first_life, bool) or not isinstance(first_life, int) or first_life < 0 or first_life + lives - 1 > 2**32 - 1:
        raise LlcpsError(f"--first-life must be a non-negative integer, not {first_life!r}")
    return tuple(range(first_life, first_life + lives))


def resolve_life(life: str | Life, *, episodes: int | None = None, conditions: Iterable[str] | None = None) -> Life:
    chosen = load_life(life) if isinstance(life, str) else life
    return chosen.with_episodes(episodes).with_conditions(None if conditions is None else list(conditions))


def run_life_job(
    *,
    store: Store,
    life: str | Life,
    lives: int = 1,
    first_life: int = 0,
    episodes: int | None = None,
    conditions: Iterable[str] | None = None,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    cache: bool = True,
    out_dir: str | Path | None = None,
    html: bool = False,
    progress: ProgressCallback | None = None,
) -> LifeRun:
    """Run ``lives`` paired lives of a life file under its conditions, then report on every
    life of that file the store holds (the same command resumes a killed run).

    Args:
        life: a shipped life's name, a life file's path, or a :class:`Life`.
        lives, first_life: lives ``first_life ..``; life N draws its episodes from seed N.
        episodes: cut each life to its first K episodes (a quick look).
        conditions: run these conditions instead of the file's.
        workers, engine, ray_address, cache, progress: see :func:`~llcps.experiments.runner.run_lives`.
        out_dir: the report's directory (default ``results/life_<name>``).
        html: also write report.html.
    """
    chosen = resolve_life(life, episodes=episodes, conditions=conditions)
    seeds = life_seeds(lives, first_life)
    summary = run_lives(store, chosen, lives=seeds, workers=workers, engine=engine, ray_address=ray_address, progress=progress, cache=cache)
    if summary.status == "interrupted":
        return LifeRun(summary, chosen)
    rows = read_rows(store, chosen)
    if not rows:
        return LifeRun(summary, chosen)
    paths, metrics = _report(rows, chosen, out_dir, html)
    return LifeRun(summary, chosen, paths, metrics)


def read_rows(store: Store, life: Life) -> list[LifeRow]:
    """Every stored episode of ``life`` (all lives, every condition) as rows."""
    return life_rows(store.list_episodes(), life=life.name, tau=life.horizon())


def _report(rows: list[LifeRow], life: Life, out_dir: str | Path | None, html: bool) -> tuple[LifeReportPaths, dict[str, Any]]:
    metrics = life_metrics(rows, last=life.last)  # None: the last quarter of the episodes stored
    target = out_dir if out_dir is not None else default_life_dir(life.name)
    paths = write_life_report(rows, metrics, target, life=life.name, description=life.description, html=html)
    return paths, {"life": life.name, **metrics.as_json()}


def report_life_job(
    *,
    store: Store,
    life: str | Life,
    out_dir: str | Path | None = None,
    html: bool = False,
    conditions: Iterable[str] | None = None,
) -> LifeReport:
    """Rebuild the report of a life file from the store's episodes, running nothing.

    Args:
        conditions: report only these conditions (the metrics cover the lives every
            reported condition holds, so a condition run on fewer lives does not cut the
            others' short); None: every condition stored.
    """
    chosen = load_life(life) if isinstance(life, str) else life
    rows = read_rows(store, chosen)
    if not rows:
        raise LlcpsError(
            f"the store holds no episode of life {chosen.name!r}",
            hint=f"run it first: `llcps life run {chosen.name} --lives 2`, or pass the --db it ran on",
        )
    if conditions is not None:
        wanted = list(dict.fromkeys(conditions))
        stored = sorted({row.condition for row in rows})
        missing = [c for c in wanted if c not in stored]
        if not wanted or missing:
            raise LlcpsError(
                f"the store holds no episode of life {chosen.name!r} under {', '.join(missing) or 'no condition'}",
                hint=f"stored conditions: {', '.join(stored)}",
            )
        rows = [row for row in rows if row.condition in wanted]
    paths, metrics = _report(rows, chosen, out_dir, html)
    return LifeReport(chosen, paths, metrics, len(rows))


@dataclass(frozen=True)
class LifeListing:
    name: str
    description: str
    families: tuple[str, ...]
    episodes: int
    p_recur: float
    probes: int | tuple[str, ...]
    conditions: tuple[str, ...]

    def as_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "families": list(self.families),
            "episodes": self.episodes,
            "p_recur": self.p_recur,
            "probes": self.probes if isinstance(self.probes, int) else list(self.probes),
            "conditions": list(self.conditions),
        }


def list_lives_job() -> list[LifeListing]:
    """Every shipped life file."""
    out = []
    for name in shipped_lives():
        life = load_life(name)
        out.append(LifeListing(life.name, life.description, life.family_names, life.episodes, life.p_recur, life.probes, life.conditions))
    return out


@dataclass(frozen=True)
class LifeShow:
    life: Life
    draw: LifeDraw | None

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.life.name, "source": self.life.source, "file": self.life.text}
        if self.draw is not None:
            out["life"] = self.draw.seed
            out["probes"] = list(self.draw.probes)
            out["episodes"] = [e.__dict__ for e in self.draw.episodes]
            out["after"] = [{"family": f, "variant": v} for f, v in self.draw.after]
        return out


def show_life_job(*, life: str, seed: int | None = None, episodes: int | None = None) -> LifeShow:
    """A life file, and with ``seed`` the episodes life number ``seed`` draws."""
    chosen = resolve_life(life, episodes=episodes)
    if seed is not None and (isinstance(seed, bool) or not 0 <= seed <= 2**32 - 1):
        raise LlcpsError(f"--life must be a seed from 0 to 2**32-1, not {seed!r}")
    return LifeShow(chosen, None if seed is None else draw_life(chosen, seed))


__all__ = [
    "condition_names",
    "LifeListing",
    "LifeReport",
    "LifeRun",
    "LifeShow",
    "default_life_dir",
    "list_lives_job",
    "read_rows",
    "report_life_job",
    "run_life_job",
    "show_life_job",
]
