"""Leave one family out: does an ordering beat the random order on novelty families it was
never tuned on?

A scenario is a novelty *family* (what resolves the novelty); its variants vary the
layout. Pretraining never sees a family (it is random layouts from the sampler's
catalog), so every family a table holds is held out of it. Per family F and per row
group (a model x measure other than the random order, explored in one ordering of
:mod:`llcps.cps.orderings`, at one pretraining size and condition), paired by scene
variant (seed N solves variant N, the same variants for every row group) with the
random order's rows:

- the median exploration trials of the ordering and of the random order, whose cost in
  a variant is the mean over its draws (permutations: the preset's ``random_draws``),
  since one permutation is a noisy estimate of what random order costs;
- the ratio ordering / random two ways: the **median of the per-variant ratios**
  ``median_v(t_model(v) / t_random(v))`` (paired: the headline number) and the
  **ratio of the medians** ``median_v t_model(v) / median_v t_random(v)``; a ratio
  above 1 means the ordering explored more than random;
- a two-sided paired Wilcoxon signed-rank test over variants, Holm-corrected across
  the families of one row group;
- when some episode ended unsolved (censored at the budget): Kaplan–Meier medians
  and a log-rank test (:mod:`llcps.analysis.survival`);
- for an ordering with sides (``hedged``), how many of its solved episodes the model's
  side resolved (the side that chose the last trial; ``resolving_pick``), so a family's
  ratio can be read as the model pointing the right way or not.

Overall, per row group: the geometric mean of the per-family median ratios
``exp(mean_F log r_F)`` and how many families have ``r_F > 1``.

Every ordering is measured against the same random-order rows: those of the random model
run in the paper's ordering (where it explores in a seeded random order), or, where a
table has none for a family, those run in the row group's own ordering.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Hashable, Iterable, TypeVar

import numpy as np

from llcps.analysis.results import ResultsTable, group_rows
from llcps.analysis.stats import holm, paired_wilcoxon
from llcps.analysis.survival import budget, kaplan_meier, logrank
from llcps.cps.orderings import ORDERINGS, PAPER_ORDERING
from llcps.cps.orderings.base import MODEL_SIDE
from llcps.experiments.design import OWN_BRANCH_CONDITIONS, RANDOM_ORDER_MODEL, condition_rank, scenario_rank
from llcps.experiments.presets import PRESETS, measure_rank, model_rank
from llcps.experiments.rows import ordering_rank
from llcps.models.measures import MEASURES
from llcps.models.registry import WORLD_MODELS

#: Which per-family ratio the overall figures (geometric mean, families > 1) use.
HEADLINE_RATIO = "median of per-variant ratios"


@dataclass(frozen=True)
class FamilyResult:
    """One row group (model, measure, ordering, pretraining size, condition) against the
    random order on one held-out family.

    Attributes:
        family: the scenario.
        ordering: the exploration ordering of the row group's episodes.
        condition: ``reset`` (pretraining only) or ``others`` (also the other families' episodes).
        n: variants both orderings solved or gave up on (the pairs).
        random_draws: the fewest permutations of the random order behind a pair (the
            random order's cost in a variant is their mean).
        median_ratio: median over variants of trials(ordering) / trials(random); 0/0 counts as 1.
        ratio_of_medians: median trials(ordering) / median trials(random).
        p_value, p_reason, p_holm: paired Wilcoxon over variants; Holm across this row group's families.
        unsolved_model, unsolved_random: episodes that ended unsolved (censored at the budget;
            the random order's over all its draws).
        km_median_model, km_median_random: Kaplan–Meier medians (None: not reached, or no censoring).
        logrank_p, logrank_reason: log-rank test, only when some episode was censored.
        default: the row group is the registries' default world model, measure and ordering.
        resolved_by_model: solved episodes whose resolving trial the ordering's model side chose.
        resolved_with_pick: solved episodes whose summary says which side chose it (0: an
            ordering without sides, or episodes from before the trace was kept).
    """

    family: str
    model: str
    measure: str
    ordering: str
    pretrain_size: int
    condition: str
    n: int
    random_draws: int
    median_model: float
    median_random: float
    median_ratio: float
    ratio_of_medians: float
    p_value: float
    p_reason: str
    p_holm: float
    unsolved_model: int
    unsolved_random: int
    km_median_model: float | None
    km_median_random: float | None
    logrank_p: float | None
    logrank_reason: str
    default: bool
    resolved_by_model: int = 0
    resolved_with_pick: int = 0


@dataclass(frozen=True)
class GeneralizationSummary:
    """One row group over every held-out family.

    Attributes:
        geomean_ratio: geometric mean of the families' median ratios (:data:`HEADLINE_RATIO`).
        worse_than_random: families whose median ratio is above 1.
    """

    model: str
    measure: str
    ordering: str
    pretrain_size: int
    condition: str
    families: int
    geomean_ratio: float
    worse_than_random: int
    default: bool


def ratio(a: float, b: float) -> float:
    """``a / b`` for exploration counts: 0/0 is 1 (neither explored), x/0 is infinite."""
    if b == 0:
        return 1.0 if a == 0 else math.inf
    return a / b


def geometric_mean(values: list[float]) -> float:
    """``exp(mean(log v))``; NaN for no values, 0 or infinity when a value is."""
    if not values:
        return math.nan
    if any(v == 0 for v in values):
        return 0.0 if not any(math.isinf(v) for v in values) else math.nan
    if any(math.isinf(v) for v in values):
        return math.inf
    return float(np.exp(np.mean(np.log(values))))


def family_results(table: ResultsTable, *, metric: str = "exploration_trials") -> tuple[FamilyResult, ...]:
    """Every row group against the random order on every family, paired by seed (= variant).

    A row group is (model, measure, ordering, pretraining size, condition). Only
    conditions that solve each family on its own branch count (``reset``, ``others``);
    the random order's rows are matched on family, condition and pretraining size (the
    random order ignores its measure), and are those of the paper's ordering for every
    row group when the table holds them (else those of the row group's own ordering).
    Empty without random rows, and for rows of presets that do not hold their scenarios
    out as families.
    """
    rows = [r for r in table if r.condition in OWN_BRANCH_CONDITIONS and r.preset in PRESETS and PRESETS[r.preset].per_family]
    random = group_rows(
        (r for r in rows if r.model == RANDOM_ORDER_MODEL), lambda r: (r.scenario, r.condition, r.pretrain_size, r.ordering)
    )
    groups = group_rows(
        (r for r in rows if r.model != RANDOM_ORDER_MODEL),
        lambda r: (r.model, r.measure, r.ordering, r.pretrain_size, r.condition, r.scenario),
    )
    out: list[FamilyResult] = []
    for (model, measure, ordering, size, condition, family), mine in groups.items():
        baseline = random.get((family, condition, size, PAPER_ORDERING)) or random.get((family, condition, size, ordering), [])
        theirs = _group(baseline, lambda r: (r.seed, r.variant))
        pairs = [(r, theirs[(r.seed, r.variant)]) for r in mine if (r.seed, r.variant) in theirs]
        if not pairs:
            continue
        a = np.array([m.metric(metric) for m, _ in pairs])
        # The random order's cost in a variant: the mean over its draws (an unsolved
        # draw counts at what it tried, so the mean is then a lower bound).
        b = np.array([np.mean([t.metric(metric) for t in draws]) for _, draws in pairs])
        p, reason = paired_wilcoxon(a, b)
        med_a, med_b = float(np.median(a)), float(np.median(b))
        solved_a = np.array([m.solved for m, _ in pairs])
        picks = [m.resolving_pick for m, _ in pairs if m.solved and m.resolving_pick]
        every_draw = [t for _, draws in pairs for t in draws]
        solved_b = np.array([t.solved for t in every_draw])
        km_a = km_b = lr = None
        lr_reason = "every episode resolved: no censoring"
        if not (solved_a.all() and solved_b.all()):
            tau = budget([m for m, _ in pairs] + every_draw)
            b_all = np.array([t.metric(metric) for t in every_draw])
            km_a = kaplan_meier(a, solved_a, tau=tau).median
            km_b = kaplan_meier(b_all, solved_b, tau=tau).median
            lr_value, lr_reason = logrank(a, solved_a, b_all, solved_b)
            lr = None if math.isnan(lr_value) else lr_value
        out.append(
            FamilyResult(
                family=family,
                model=model,
                measure=measure,
                ordering=ordering,
                pretrain_size=size,
                condition=condition,
                n=len(pairs),
                random_draws=min(len(draws) for _, draws in pairs),
                median_model=med_a,
                median_random=med_b,
                median_ratio=float(np.median([ratio(x, y) for x, y in zip(a, b)])),
                ratio_of_medians=ratio(med_a, med_b),
                p_value=p,
                p_reason=reason,
                p_holm=math.nan,
                unsolved_model=int((~solved_a).sum()),
                unsolved_random=int((~solved_b).sum()),
                km_median_model=km_a,
                km_median_random=km_b,
                logrank_p=lr,
                logrank_reason="" if lr is not None else lr_reason,
                default=(model, measure, ordering) == (WORLD_MODELS.default, MEASURES.default, ORDERINGS.default),
                resolved_by_model=sum(pick == MODEL_SIDE for pick in picks),
                resolved_with_pick=len(picks),
            )
        )
    out.sort(key=_order)
    return _holm_per_group(out)


def row_group(r: FamilyResult | GeneralizationSummary) -> tuple[str, str, str, int, str]:
    """What one line of comparisons is about: (model, measure, ordering, pretraining size, condition)."""
    return (r.model, r.measure, r.ordering, r.pretrain_size, r.condition)


def _order(r: FamilyResult) -> tuple:
    return (
        not r.default,
        model_rank(r.model),
        measure_rank(r.measure),
        ordering_rank(r.ordering),
        -r.pretrain_size,
        condition_rank(r.condition),
        scenario_rank(r.family),
    )


def shows_ordering(rows: Iterable[FamilyResult | GeneralizationSummary]) -> bool:
    """Whether the rows' labels name the ordering: when they are not all of the paper's
    ordering (a report of one ``ranked`` run reads as before orderings were recorded)."""
    return any(r.ordering != PAPER_ORDERING for r in rows)


def group_label(r: FamilyResult | GeneralizationSummary, *, ordering: bool = True) -> str:
    """A row group for people: ``nb / goal-directed / trial-and-error / p200 / reset``
    (without the ordering when ``ordering`` is false)."""
    return " / ".join((r.model, r.measure, *((r.ordering,) if ordering else ()), f"p{r.pretrain_size}", r.condition))


T = TypeVar("T")
K = TypeVar("K", bound=Hashable)


def _group(items: Iterable[T], key: Callable[[T], K]) -> dict[K, list[T]]:
    groups: dict[K, list[T]] = {}
    for item in items:
        groups.setdefault(key(item), []).append(item)
    return groups


def _holm_per_group(results: list[FamilyResult]) -> tuple[FamilyResult, ...]:
    """Holm's correction across the families of each row group (one family of tests per row group)."""
    adjusted: dict[int, float] = {}
    for members in _group(range(len(results)), lambda i: row_group(results[i])).values():
        for i, p in zip(members, holm(results[i].p_value for i in members)):
            adjusted[i] = p
    return tuple(replace(r, p_holm=adjusted[i]) for i, r in enumerate(results))


def generalization_summary(results: tuple[FamilyResult, ...]) -> tuple[GeneralizationSummary, ...]:
    """Per row group: the geometric mean of its families' median ratios and the families above 1."""
    out = []
    for (model, measure, ordering, size, condition), members in _group(results, row_group).items():
        ratios = [r.median_ratio for r in members]
        out.append(
            GeneralizationSummary(
                model=model,
                measure=measure,
                ordering=ordering,
                pretrain_size=size,
                condition=condition,
                families=len(members),
                geomean_ratio=geometric_mean(ratios),
                worse_than_random=sum(r > 1 for r in ratios),
                default=members[0].default,
            )
        )
    return tuple(out)


__all__ = [
    "HEADLINE_RATIO",
    "FamilyResult",
    "GeneralizationSummary",
    "family_results",
    "generalization_summary",
    "geometric_mean",
    "group_label",
    "ratio",
    "row_group",
    "shows_ordering",
]
