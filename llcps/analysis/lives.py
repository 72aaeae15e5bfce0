"""The metrics of lives: learning curves, AUC, forward transfer, forgetting and the
novelty reaction, each aggregated over lives with statistics that resample *lives*.

Inputs are :class:`LifeRow` s, one per stored episode of a life (``phase`` ``life``)
or of the re-solves after it (``after``), read back from the store by
:func:`life_rows` or from ``episodes.csv`` / ``after.csv``. Formulas (docs/experiments.md):

- an episode's count N_k is its exploration trials; an unsolved episode is censored
  and counts as tau (the horizon);
- AUC_k = (tau - min(N_k, tau) + 1) / (tau + 1), in (0, 1]: 1 for an episode that
  needs no exploration; AUC_life is the mean of a life's AUC_k;
- forward transfer FT = (AUC - AUC_reset) / (1 - AUC_reset), over the first
  encounters and over the recurrences separately, AUC being the mean over lives of
  each life's mean AUC over those episodes (``reset`` solves the same episodes);
- forgetting of a family = AUC of its first recurrence in the life (the episode right
  after it was learned) minus AUC of its re-solve (a fresh variant) after the life;
  > 0: slower after the life. Its original condition after the life should need 0;
- NRP = mean AUC of the last m episodes over reset's mean AUC on the same episodes
  (the pretrained model on the same families);
- the curve ratio: (mean N of the last quarter / mean N of the first quarter), probes
  left out, over the same ratio for ``reset``.

Every interval is a percentile bootstrap over lives (a life is resampled with all its
episodes and all its conditions); the paired test is Wilcoxon over lives; censored
counts are compared by a log-rank test stratified by episode index (``statsmodels``
``survdiff``); per-family tests are corrected with Holm's method.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, fields
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from llcps.analysis.stats import cell_rng, holm, paired_wilcoxon
from llcps.analysis.survival import kaplan_meier
from llcps.experiments.design import rank_by
from llcps.experiments.life import LIFE_CONDITIONS

#: Bootstrap resamples of every life-level interval.
LIFE_RESAMPLES = 2000
#: The reference condition of transfer: every episode from the pretraining point.
REFERENCE = "reset"


@dataclass(frozen=True)
class LifeRow:
    """One episode of one life under one condition (``episodes.csv`` / ``after.csv``)."""

    life: int
    condition: str
    episode: int  # -1 for a re-solve after the life
    family: str
    variant: int
    first_encounter: bool
    probe: bool
    episode_condition: str  # novelty or original
    exploration_trials: int
    solved: bool
    censored: bool
    wall_seconds: float
    sim_seconds: float
    tau: int
    phase: str = "life"  # life, or after (the forgetting re-solves)
    status: str = ""

    @property
    def count(self) -> float:
        """N_k: the exploration trials, tau for a censored episode."""
        return float(self.tau) if self.censored else float(self.exploration_trials)

    @property
    def auc(self) -> float:
        return auc(self.count, self.tau)


#: Columns of episodes.csv, in order.
COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(LifeRow))


def condition_rank(condition: str) -> tuple[int, str]:
    """Sort key putting conditions in :data:`LIFE_CONDITIONS` order, others after by name."""
    return rank_by(tuple(LIFE_CONDITIONS), condition)


def auc(count: float, tau: float) -> float:
    """AUC_k = (tau - min(N, tau) + 1) / (tau + 1)."""
    return (tau - min(count, tau) + 1.0) / (tau + 1.0)


def row_from_episode(summary: Mapping[str, Any], status: str, tau: int) -> LifeRow | None:
    """The row of one stored episode whose summary says where in a life it is (else None)."""
    place = summary.get("life")
    if not isinstance(place, Mapping):
        return None
    try:
        solved = bool(summary.get("solved", status == "solved"))
        return LifeRow(
            life=int(place["life"]),
            condition=str(place["condition"]),
            episode=-1 if place.get("episode") is None else int(place["episode"]),
            family=str(place["family"]),
            variant=int(place["variant"]),
            first_encounter=bool(place.get("first_encounter", False)),
            probe=bool(place.get("probe", False)),
            episode_condition=str(summary.get("condition", "novelty")),
            exploration_trials=int(summary.get("exploration_trials", 0)),
            solved=solved,
            censored=not solved,
            wall_seconds=float(summary.get("wall_seconds", 0.0)),
            sim_seconds=float(summary.get("sim_seconds", 0.0)),
            tau=int(tau),
            phase=str(place.get("phase", "life")),
            status=str(status),
        )
    except (KeyError, TypeError, ValueError):
        return None


def life_rows(episodes: Iterable[Any], *, life: str, tau: int) -> list[LifeRow]:
    """Rows of the stored episodes of life file ``life`` (store ``EpisodeRecord`` s), in
    (condition, life, phase, episode) order; a re-solved episode keeps its latest record."""
    chosen: dict[tuple[Any, ...], tuple[int, LifeRow]] = {}
    for record in episodes:
        summary = record.summary if isinstance(record.summary, Mapping) else {}
        place = summary.get("life")
        if not isinstance(place, Mapping) or place.get("name") != life or record.status == "running":
            continue
        row = row_from_episode(summary, record.status, tau)
        if row is None:
            continue
        key = (row.condition, row.life, row.phase, row.episode, row.family, row.episode_condition)
        if key not in chosen or chosen[key][0] < record.id:
            chosen[key] = (record.id, row)
    return sorted((r for _, r in chosen.values()), key=_order)


def _order(row: LifeRow) -> tuple[Any, ...]:
    return (row.condition, row.life, row.phase != "life", row.episode, row.family, row.episode_condition)


def row_as_csv(row: LifeRow) -> dict[str, Any]:
    data = asdict(row)
    for key in ("first_encounter", "probe", "solved", "censored"):
        data[key] = str(data[key]).lower()
    return data


def row_from_csv(data: Mapping[str, str], where: str) -> LifeRow:
    """A row of episodes.csv (every value untrusted: a bad one is an error naming it)."""
    from llcps.errors import LlcpsError

    def boolean(key: str) -> bool:
        text = str(data.get(key, "")).strip().lower()
        if text not in ("true", "false", "1", "0"):
            raise LlcpsError(f"{where}: {key} must be true or false, not {text!r}")
        return text in ("true", "1")

    try:
        return LifeRow(
            life=int(data["life"]),
            condition=str(data["condition"])[:64],
            episode=int(data["episode"]),
            family=str(data["family"])[:64],
            variant=int(data["variant"]),
            first_encounter=boolean("first_encounter"),
            probe=boolean("probe"),
            episode_condition=str(data.get("episode_condition") or "novelty")[:32],
            exploration_trials=int(data["exploration_trials"]),
            solved=boolean("solved"),
            censored=boolean("censored"),
            wall_seconds=float(data["wall_seconds"]),
            sim_seconds=float(data["sim_seconds"]),
            tau=int(data["tau"]),
            phase=str(data.get("phase") or "life")[:16],
            status=str(data.get("status") or "")[:32],
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise LlcpsError(f"{where}: a row lacks or mangles {exc}", hint="episodes.csv as `llcps life run` writes it") from None


# --- aggregation --------------------------------------------------------------------


@dataclass(frozen=True)
class Estimate:
    """A value over lives with its 95% bootstrap interval (NaN when it cannot be computed)."""

    value: float
    low: float = math.nan
    high: float = math.nan
    n: int = 0

    def as_json(self) -> dict[str, Any]:
        return {"value": _finite(self.value), "low": _finite(self.low), "high": _finite(self.high), "n": self.n}


def _finite(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), 6)


def bootstrap_lives(
    n: int, statistic: Callable[[np.ndarray], float], *, rng: np.random.Generator, resamples: int = LIFE_RESAMPLES
) -> Estimate:
    """``statistic`` of lives ``0..n-1`` and its percentile interval, resampling lives with replacement."""
    everyone = np.arange(n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        value = float(statistic(everyone)) if n else math.nan
        if n < 2 or not math.isfinite(value):
            return Estimate(value, math.nan, math.nan, n)
        draws = np.array([statistic(rng.integers(0, n, n)) for _ in range(resamples)], dtype=float)
    draws = draws[np.isfinite(draws)]
    if draws.size < resamples // 2:
        return Estimate(value, math.nan, math.nan, n)
    low, high = np.percentile(draws, [2.5, 97.5])
    return Estimate(value, float(low), float(high), n)


class LifeData:
    """The rows of one life file as arrays: lives x episodes per condition."""

    def __init__(self, rows: Iterable[LifeRow]) -> None:
        rows = list(rows)
        self.rows = rows
        self.life_rows = [r for r in rows if r.phase == "life"]
        self.after_rows = [r for r in rows if r.phase == "after"]
        self.conditions = tuple(sorted(dict.fromkeys(r.condition for r in self.life_rows), key=condition_rank))
        by_condition: dict[str, set[int]] = {}
        for r in self.life_rows:
            by_condition.setdefault(r.condition, set()).add(r.life)
        # Lives every condition finished: the statistics pair them.
        common = set.intersection(*by_condition.values()) if by_condition else set()
        self.lives = tuple(sorted(common))
        self.episodes = 1 + max((r.episode for r in self.life_rows), default=-1)
        self.tau = max((r.tau for r in rows), default=1)
        index = {life: i for i, life in enumerate(self.lives)}
        shape = (len(self.lives), self.episodes)
        self.count: dict[str, np.ndarray] = {}
        self.auc: dict[str, np.ndarray] = {}
        self.solved: dict[str, np.ndarray] = {}
        for c in self.conditions:
            self.count[c] = np.full(shape, np.nan)
            self.auc[c] = np.full(shape, np.nan)
            self.solved[c] = np.zeros(shape, dtype=bool)
        self.family = np.full(shape, "", dtype=object)
        self.first = np.zeros(shape, dtype=bool)
        self.probe = np.zeros(shape, dtype=bool)
        for r in self.life_rows:
            if r.life not in index:
                continue
            i = index[r.life]
            self.count[r.condition][i, r.episode] = r.count
            self.auc[r.condition][i, r.episode] = r.auc
            self.solved[r.condition][i, r.episode] = r.solved
            self.family[i, r.episode] = r.family
            self.first[i, r.episode] = r.first_encounter
            self.probe[i, r.episode] = r.probe

    def mean_over(self, values: np.ndarray, mask: np.ndarray, lives: np.ndarray) -> float:
        """Mean over ``lives`` of each life's mean of ``values`` where ``mask`` (lives without any: left out)."""
        v, m = values[lives], mask[lives]
        sums = np.where(m, v, 0.0).sum(axis=1)
        counts = m.sum(axis=1)
        ok = counts > 0
        return float(np.mean(sums[ok] / counts[ok])) if ok.any() else math.nan


@dataclass(frozen=True)
class CurvePoint:
    """The learning curve of one condition at one episode index, over lives."""

    condition: str
    episode: int
    mean: float
    low: float
    high: float
    km_median: float | None
    km_low: float | None
    km_high: float | None
    lives: int


@dataclass(frozen=True)
class ConditionMetrics:
    """The figures of one condition over lives (intervals: bootstrap over lives)."""

    condition: str
    lives: int
    auc_life: Estimate
    #: AUC_life minus reset's, and the paired Wilcoxon p over lives.
    auc_difference: Estimate
    wilcoxon_p: float
    #: Log-rank p of the censored counts against reset, stratified by episode index.
    logrank_p: float
    ft_first: Estimate
    ft_recurrence: Estimate
    #: (last / first quarter mean N, probes out) over reset's same ratio.
    curve_ratio: Estimate
    nrp: Estimate
    forgetting: Estimate
    #: Original-condition re-solves after the life needing no exploration, of those run.
    originals_kept: int = 0
    originals: int = 0

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"condition": self.condition, "lives": self.lives}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, Estimate):
                out[f.name] = value.as_json()
            elif f.name not in out:
                out[f.name] = _finite(value) if isinstance(value, float) else value
        return out


@dataclass(frozen=True)
class FamilyMetrics:
    """One condition against reset on one family's episodes, over the lives that met it."""

    condition: str
    family: str
    lives: int
    auc: float
    auc_reset: float
    difference: Estimate
    p: float
    p_holm: float = math.nan
    #: AUC of the family's first recurrence minus AUC of its re-solve after the life, over lives.
    forgetting: Estimate = Estimate(math.nan)

    def as_json(self) -> dict[str, Any]:
        return {
            "condition": self.condition,
            "family": self.family,
            "lives": self.lives,
            "auc": _finite(self.auc),
            "auc_reset": _finite(self.auc_reset),
            "difference": self.difference.as_json(),
            "p": _finite(self.p),
            "p_holm": _finite(self.p_holm),
            "forgetting": self.forgetting.as_json(),
        }


@dataclass(frozen=True)
class LifeMetrics:
    """Everything ``life report`` shows."""

    lives: tuple[int, ...]
    episodes: int
    tau: int
    last: int
    conditions: tuple[ConditionMetrics, ...]
    curve: tuple[CurvePoint, ...]
    families: tuple[FamilyMetrics, ...]

    def as_json(self) -> dict[str, Any]:
        return {
            "lives": list(self.lives),
            "episodes": self.episodes,
            "tau": self.tau,
            "last": self.last,
            "conditions": [c.as_json() for c in self.conditions],
            "curve": [asdict(p) for p in self.curve],
            "families": [f.as_json() for f in self.families],
        }


def _ft(a: float, r: float) -> float:
    return (a - r) / (1.0 - r) if r < 1.0 else math.nan


def learning_curve(data: LifeData, condition: str, *, seed: int = 0) -> list[CurvePoint]:
    """Mean N_k per episode index with a bootstrap band over lives, and the Kaplan–Meier
    median with its band (where the pointwise 95% band of S crosses 1/2)."""
    out = []
    counts = data.count[condition]
    for k in range(data.episodes):
        column = counts[:, k]
        rng = cell_rng(seed, "curve", condition, k)
        mean = bootstrap_lives(column.size, lambda idx: float(np.mean(column[idx])), rng=rng)
        solved = data.solved[condition][:, k]
        km = kaplan_meier(column, solved, tau=data.tau) if column.size else None
        out.append(
            CurvePoint(
                condition, k, mean.value, mean.low, mean.high,
                None if km is None else km.median, _crossing(km, km.ci_low) if km else None,
                _crossing(km, km.ci_high) if km else None, column.size,
            )
        )  # fmt: skip
    return out


def _crossing(km: Any, band: Sequence[float]) -> float | None:
    for t, s in zip(km.times, band):
        if s <= 0.5:
            return float(t)
    return None


def stratified_logrank(data: LifeData, condition: str) -> float:
    """Log-rank p of ``condition`` against reset over every episode, stratified by episode index."""
    if condition == REFERENCE or REFERENCE not in data.count or not data.lives:
        return math.nan
    from statsmodels.duration.survfunc import survdiff

    times, status, group, strata = [], [], [], []
    for g, c in enumerate((condition, REFERENCE)):
        counts, solved = data.count[c], data.solved[c]
        for k in range(data.episodes):
            times.extend(counts[:, k].tolist())
            status.extend(solved[:, k].astype(int).tolist())
            group.extend([g] * counts.shape[0])
            strata.extend([k] * counts.shape[0])
    if not any(status) or (
        np.array_equal(data.count[condition], data.count[REFERENCE]) and np.array_equal(data.solved[condition], data.solved[REFERENCE])
    ):
        return math.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            _, p = survdiff(np.array(times), np.array(status), np.array(group), strata=np.array(strata))
        except (ValueError, ZeroDivisionError, np.linalg.LinAlgError):
            return math.nan
    return float(p) if math.isfinite(p) else math.nan


def forgetting_pairs(data: LifeData, condition: str) -> dict[tuple[int, str], float]:
    """(life index, family) -> AUC of the family's first recurrence in the life minus AUC of
    its re-solve after the life, for the families that recurred and were re-solved."""
    after = {(r.life, r.family): r for r in data.after_rows if r.condition == condition and r.episode_condition == "novelty"}
    out: dict[tuple[int, str], float] = {}
    if condition not in data.auc:
        return out
    for i, life in enumerate(data.lives):
        seen: set[str] = set()
        for k in range(data.episodes):
            family = str(data.family[i, k])
            if data.first[i, k]:
                seen.add(family)
            elif family in seen and (life, family) in after:
                out[(i, family)] = float(data.auc[condition][i, k] - after[(life, family)].auc)
                seen.discard(family)
    return out


def forgetting_by_life(data: LifeData, condition: str) -> tuple[np.ndarray, int, int]:
    """Per life (in ``data.lives`` order): the mean of :func:`forgetting_pairs` over its
    families, NaN for a life without any; and the original-condition re-solves after the
    life that needed no exploration, of those run."""
    lives = set(data.lives)
    originals = [r for r in data.after_rows if r.condition == condition and r.episode_condition == "original" and r.life in lives]
    kept = sum(1 for r in originals if r.solved and r.exploration_trials == 0)
    values = np.full(len(data.lives), np.nan)
    by_life: dict[int, list[float]] = {}
    for (i, _), diff in forgetting_pairs(data, condition).items():
        by_life.setdefault(i, []).append(diff)
    for i, diffs in by_life.items():
        values[i] = float(np.mean(diffs))
    return values, kept, len(originals)


def condition_metrics(data: LifeData, condition: str, *, last: int, seed: int = 0) -> ConditionMetrics:
    n = len(data.lives)
    a = data.auc[condition]
    everything = np.ones_like(data.first)
    reference = data.auc.get(REFERENCE)
    quarter = max(1, data.episodes // 4)
    first_q = np.zeros_like(data.first)
    first_q[:, :quarter] = True
    last_q = np.zeros_like(data.first)
    last_q[:, data.episodes - quarter :] = True
    tail = np.zeros_like(data.first)
    tail[:, data.episodes - last :] = True
    regular = ~data.probe

    def rng(what: str) -> np.random.Generator:
        return cell_rng(seed, "life", condition, what)

    auc_life = bootstrap_lives(n, lambda idx: data.mean_over(a, everything, idx), rng=rng("auc"))
    if reference is None or condition == REFERENCE:
        nan = Estimate(math.nan)
        difference, p, ft_first, ft_rec, ratio, nrp = nan, math.nan, nan, nan, nan, nan
    else:
        per_life = np.nanmean(a, axis=1)
        per_life_r = np.nanmean(reference, axis=1)
        difference = bootstrap_lives(n, lambda idx: float(np.mean(per_life[idx] - per_life_r[idx])), rng=rng("difference"))
        p, _ = paired_wilcoxon(per_life, per_life_r)
        ft_first = bootstrap_lives(
            n, lambda idx: _ft(data.mean_over(a, data.first, idx), data.mean_over(reference, data.first, idx)), rng=rng("ft-first")
        )
        ft_rec = bootstrap_lives(
            n, lambda idx: _ft(data.mean_over(a, ~data.first, idx), data.mean_over(reference, ~data.first, idx)), rng=rng("ft-rec")
        )
        cnt, cnt_r = data.count[condition], data.count[REFERENCE]

        def quarter_ratio(idx: np.ndarray) -> float:
            mine = data.mean_over(cnt, last_q & regular, idx) / data.mean_over(cnt, first_q & regular, idx)
            theirs = data.mean_over(cnt_r, last_q & regular, idx) / data.mean_over(cnt_r, first_q & regular, idx)
            return mine / theirs if theirs else math.nan

        ratio = bootstrap_lives(n, quarter_ratio, rng=rng("ratio"))
        nrp = bootstrap_lives(n, lambda idx: data.mean_over(a, tail, idx) / data.mean_over(reference, tail, idx), rng=rng("nrp"))
    per_life_forgetting, kept, originals = forgetting_by_life(data, condition)
    has = np.isfinite(per_life_forgetting)
    forgetting = (
        bootstrap_lives(
            n, lambda idx: float(np.mean(per_life_forgetting[idx][has[idx]])) if has[idx].any() else math.nan, rng=rng("forgetting")
        )
        if has.any()
        else Estimate(math.nan)
    )
    return ConditionMetrics(
        condition, n, auc_life, difference, p, stratified_logrank(data, condition), ft_first, ft_rec, ratio, nrp, forgetting,
        kept, originals,
    )  # fmt: skip


def family_metrics(data: LifeData, *, seed: int = 0) -> list[FamilyMetrics]:
    """Per condition and family: each life's mean AUC over the family's episodes against
    reset's, a paired Wilcoxon over the lives that met it, Holm across families."""
    reference = data.auc.get(REFERENCE)
    if reference is None:
        return []
    out: list[FamilyMetrics] = []
    families = sorted({str(f) for f in data.family.ravel() if f})
    for condition in data.conditions:
        if condition == REFERENCE:
            continue
        rows = []
        pairs = forgetting_pairs(data, condition)
        for family in families:
            forgot = np.array([v for (_, f), v in pairs.items() if f == family])
            forgetting = bootstrap_lives(
                forgot.size, lambda idx: float(np.mean(forgot[idx])), rng=cell_rng(seed, "forgetting", condition, family)
            )
            mask = data.family == family
            met = mask.any(axis=1)
            mine = np.array([np.mean(data.auc[condition][i][mask[i]]) for i in np.nonzero(met)[0]])
            theirs = np.array([np.mean(reference[i][mask[i]]) for i in np.nonzero(met)[0]])
            diff = mine - theirs
            estimate = bootstrap_lives(
                diff.size, lambda idx: float(np.mean(diff[idx])), rng=cell_rng(seed, "family", condition, family)
            )
            p, _ = paired_wilcoxon(mine, theirs)
            rows.append(
                FamilyMetrics(condition, family, int(met.sum()), float(np.mean(mine)) if mine.size else math.nan,
                              float(np.mean(theirs)) if theirs.size else math.nan, estimate, p, forgetting=forgetting)
            )  # fmt: skip
        adjusted = holm([r.p for r in rows])
        out.extend(FamilyMetrics(**{**r.__dict__, "p_holm": q}) for r, q in zip(rows, adjusted))
    return out


def life_metrics(rows: Iterable[LifeRow], *, last: int | None = None, seed: int = 0) -> LifeMetrics:
    """Every metric of a life file's rows; ``last``: m of the novelty reaction (default: the last quarter)."""
    data = LifeData(rows)
    m = min(data.episodes, last or max(1, data.episodes // 4)) if data.episodes else 0
    conditions = tuple(condition_metrics(data, c, last=m, seed=seed) for c in data.conditions) if data.lives else ()
    curve = tuple(p for c in data.conditions for p in learning_curve(data, c, seed=seed)) if data.lives else ()
    return LifeMetrics(data.lives, data.episodes, data.tau, m, conditions, curve, tuple(family_metrics(data, seed=seed)))


__all__ = [
    "COLUMNS",
    "ConditionMetrics",
    "CurvePoint",
    "Estimate",
    "FamilyMetrics",
    "LifeData",
    "LifeMetrics",
    "LifeRow",
    "auc",
    "bootstrap_lives",
    "life_metrics",
    "life_rows",
    "row_as_csv",
    "row_from_csv",
]
