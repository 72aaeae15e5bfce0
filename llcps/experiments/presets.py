"""Presets: the named grids an experiment runs, and the seeds a run takes.

A preset crosses world models x measures x pretraining sizes x conditions
(:mod:`llcps.experiments.design`) and fixes the exploration budget, the pretraining
pool and a default number of seeds. ``paper`` is the paper's Figure 2 design run over
many seeds; the others add models, measures and baselines. :data:`PRESETS` is the one
list the CLI's choices, the docs and the tests read.

Names of world models and measures are plain strings in a preset; :func:`validate_preset`
checks them against the registries in :mod:`llcps.models`, and the models beyond the
paper's come from the world-model registry itself.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable

from llcps.cps.candidates import candidate_space_size
from llcps.cps.orderings import ORDERINGS, PAPER_ORDERING
from llcps.domain import MAX_SEED
from llcps.errors import LlcpsError, UnknownNameError
from llcps.experiments.design import (
    MAX_DRAWS,
    PAPER_CONDITIONS,
    PAPER_SCENARIOS,
    RANDOM_ORDER_MODEL,
    Cell,
    Sequence,
    check_scenario_name,
    rank_by,
)
from llcps.models.measures import MEASURES, PAPER_MEASURES
from llcps.models.registry import PAPER_MODELS, WORLD_MODELS
from llcps.registry import Registry

#: 200 pretraining points ("Apriori Training") and 4 ("No Apriori Training").
PAPER_PRETRAIN_SIZES: tuple[int, ...] = (200, 4)
#: Most seeds one run may ask for.
MAX_SEEDS = 10_000


@dataclass(frozen=True)
class Preset:
    """A named grid: models x measures x pretraining sizes x conditions, and a default seed count."""

    name: str
    models: tuple[str, ...]
    measures: tuple[str, ...]
    pretrain_sizes: tuple[int, ...]
    conditions: tuple[str, ...] = PAPER_CONDITIONS
    default_seeds: int = 20
    #: Most exploration trials per episode (an unsolved episode records this many);
    #: None: the whole candidate space (:func:`llcps.cps.candidates.candidate_space_size`).
    budget: int | None = 150
    #: Random interactions drawn per seed; every pretraining set of the seed is this pool
    #: or a subset of it (the paper's 4 points are one per action from its 200).
    pretrain_pool: int = 200
    #: Exploration trials between refits of the world model within an episode.
    refit_every: int = 1
    #: The scenarios each sequence solves, in order: names, aliases or paths of .toml
    #: files; None: every shipped scenario (:data:`llcps.scenarios.SCENARIOS`).
    scenarios: tuple[str, ...] | None = PAPER_SCENARIOS
    #: Whether each scenario is a held-out novelty family, reported against the random
    #: order family by family (leave one family out).
    per_family: bool = False
    #: The exploration ordering of every episode (:mod:`llcps.cps.orderings`): the paper's
    #: ranking for the paper's presets, so their reproduction stays comparable.
    ordering: str = PAPER_ORDERING
    #: Whether exploration tries last the candidates the arm would refuse (SolveConfig's
    #: ``reach_check``): not the paper's agent, which tries every candidate in order.
    reach_check: bool = False
    #: Permutations of the random order run per seed (draws of the random model's seed,
    #: :attr:`~llcps.experiments.design.Sequence.draw`): one draw is a noisy estimate of
    #: what random order costs, and a comparison against it inherits the noise.
    random_draws: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.refit_every, bool) or not isinstance(self.refit_every, int) or self.refit_every < 1:
            raise LlcpsError(f"preset {self.name!r}: refit_every must be a positive integer, not {self.refit_every!r}")
        if self.budget is not None and (isinstance(self.budget, bool) or not isinstance(self.budget, int) or self.budget < 0):
            raise LlcpsError(f"preset {self.name!r}: the budget must be a non-negative integer, not {self.budget!r}")
        if self.pretrain_sizes and self.pretrain_pool < max(self.pretrain_sizes):
            raise LlcpsError(
                f"preset {self.name!r}: a pool of {self.pretrain_pool} random interactions cannot give "
                f"a pretraining set of {max(self.pretrain_sizes)}",
                hint="make pretrain_pool at least the largest pretraining size",
            )

        draws = self.random_draws
        if isinstance(draws, bool) or not isinstance(draws, int) or not 1 <= draws <= MAX_DRAWS:
            raise LlcpsError(
                f"preset {self.name!r}: random_draws must be a whole number from 1 to {MAX_DRAWS}, not {draws!r}",
                hint="pass --random-draws 1 or more",
            )

    def exploration_budget(self) -> int:
        """The budget as a number (None resolves to the size of the candidate space)."""
        if self.budget is not None:
            return self.budget
        return candidate_space_size()  # builds the scenarios' scenes

    def cells(self) -> tuple[Cell, ...]:
        """Every cell, in a fixed order (model, measure, pretraining size, condition)."""
        return tuple(
            Cell(model, measure, size, condition)
            for model in self.models
            for measure in self.measures
            for size in self.pretrain_sizes
            for condition in self.conditions
        )

    def scenario_names(self) -> tuple[str, ...]:
        """The names of the scenarios a sequence solves (files read for their names)."""
        return tuple(name for name, _ in resolve_scenarios(self.scenarios))

    def with_scenarios(self, scenarios: Iterable[str] | None) -> Preset:
        """This preset solving ``scenarios`` (names, aliases or .toml paths) instead; None: unchanged."""
        if scenarios is None:
            return self
        chosen = tuple(scenarios)
        resolve_scenarios(chosen)  # check now: an unknown name fails before anything runs
        return replace(self, scenarios=chosen)

    def with_ordering(self, ordering: str | None) -> Preset:
        """This preset exploring in ``ordering`` instead (``experiment run --ordering``); None: unchanged."""
        if ordering is None:
            return self
        if ordering not in ORDERINGS:
            raise UnknownNameError("ordering", ordering, list(ORDERINGS))
        return replace(self, ordering=ordering)

    def with_random_draws(self, draws: int | None) -> Preset:
        """This preset running ``draws`` permutations of the random order per seed
        (``experiment run --random-draws``); None: unchanged. Refused where the grid has
        no random-order cell, where more than one draw would change nothing."""
        if draws is None:
            return self
        if draws > 1 and RANDOM_ORDER_MODEL not in self.models:
            raise LlcpsError(
                f"preset {self.name!r} has no random-order cell for --random-draws {draws} to draw again",
                hint="--random-draws goes with a preset that runs the random order (e.g. generalization, vs_random)",
            )
        return replace(self, random_draws=draws)

    def with_others(self) -> Preset:
        """This preset with ``reset`` replaced by ``others``: each held-out scenario is solved
        after the list's other scenarios on its branch (``experiment run --with-others``)."""
        if "reset" not in self.conditions:
            raise LlcpsError(
                f"preset {self.name!r} has no reset condition for --with-others to replace",
                hint="--with-others goes with a preset that solves each scenario from the pretraining set (e.g. generalization)",
            )
        return replace(self, conditions=tuple(dict.fromkeys("others" if c == "reset" else c for c in self.conditions)))

    def sequences(self, seeds: int | Iterable[int] | None = None, *, variants: bool = False) -> tuple[Sequence, ...]:
        """Every sequence of the grid; seeds grouped outermost so a partial run covers all cells.

        Args:
            seeds: a count ``n`` (seeds ``0..n-1``), explicit seeds, or ``None`` for the default count.
            variants: solve seed N's scenarios in scene variant N (paired, not crossed:
                one variant per seed); otherwise every seed uses the canonical scenes.
        """
        chosen = seed_list(self.default_seeds if seeds is None else seeds)
        names = self.scenario_names()
        return tuple(
            Sequence(self.name, cell, seed, seed if variants else 0, names, draw=draw)
            for seed in chosen
            for cell in self.cells()
            for draw in range(self.random_draws if cell.model == RANDOM_ORDER_MODEL else 1)
        )


def resolve_scenarios(scenarios: Iterable[str] | None) -> tuple[tuple[str, str], ...]:
    """``(name, source)`` of each scenario: its name, and what a worker passes to
    :func:`llcps.scenarios.get_scenario` (the name, or a .toml file's absolute path).

    None stands for every shipped scenario. Shipped names and aliases are read without
    checking the files (cheap); a path is read and checked. An unknown name is an error
    listing the known ones; a scenario named twice is an error.
    """
    from llcps.scenarios import get_scenario, is_path, shipped_names

    shipped = shipped_names()
    aliases = {alias: name for name, alias in shipped.items() if alias}
    chosen = tuple(shipped) if scenarios is None else tuple(scenarios)
    if not chosen:
        raise LlcpsError("no scenarios to run", hint=f"name one or more of: {', '.join(shipped)}")
    out: list[tuple[str, str]] = []
    for item in chosen:
        item = item.strip()
        if item in shipped or item in aliases:
            name = aliases.get(item, item)
            out.append((name, name))
        elif is_path(item):
            scenario = get_scenario(item)
            path = str(Path(item).resolve())
            out.append((scenario.name, scenario.name if scenario.name in shipped else path))
        else:
            raise UnknownNameError(
                "scenario", item, tuple(f"{n} ({a})" if a else n for n, a in shipped.items()) + ("or a path to a .toml file",)
            )
        check_scenario_name(out[-1][0])
    names = [name for name, _ in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise LlcpsError(f"scenario {', '.join(twice)} is named twice", hint="name each scenario once")
    return tuple(out)


def seed_list(seeds: int | Iterable[int]) -> tuple[int, ...]:
    """Seeds ``0..n-1`` for a count ``n``, or the given seeds (non-empty, no repeats)."""
    if isinstance(seeds, bool):
        raise LlcpsError(f"seeds must be a count or a list of integers, not {seeds!r}")
    if isinstance(seeds, int):
        if seeds < 1:
            raise LlcpsError(f"the number of seeds must be at least 1, not {seeds}", hint="pass --seeds 1 or more")
        return tuple(range(seeds))
    chosen = tuple(seeds)
    if not chosen or len(set(chosen)) != len(chosen):
        raise LlcpsError("seeds must be a non-empty list without repeats")
    return chosen


#: The registered world models beyond the paper's two (the random order and the
#: baselines), in the registry's order.
OTHER_MODELS: tuple[str, ...] = tuple(name for name, entry in WORLD_MODELS.items() if not entry.paper)

#: A budget larger than any scenario's candidate space: the episode ends when every
#: candidate was tried (an unsolved episode records how many there were).
WHOLE_SPACE = 100_000

#: Exploration trials between world-model refits in the paper's grids. The paper updates
#: its models during exploration without saying how often; refitting the network after
#: every trial would make it 80 % of a grid's cost (0.6 s a refit at 200-500 trials).
GRID_REFIT_EVERY = 10

PRESETS: Registry[Preset] = Registry(
    "preset",
    {
        "paper": Preset(
            "paper", PAPER_MODELS, PAPER_MEASURES, PAPER_PRETRAIN_SIZES, default_seeds=20, refit_every=GRID_REFIT_EVERY
        ),
        "full": Preset(
            "full",
            PAPER_MODELS + OTHER_MODELS,
            PAPER_MEASURES + (MEASURES.default,),
            PAPER_PRETRAIN_SIZES,
            default_seeds=20,
            refit_every=GRID_REFIT_EVERY,
        ),
        # Model-guided exploration against no model, scenario by scenario: each episode starts
        # from the seed's 200 random pretraining interactions (condition reset), with the
        # whole candidate space as budget so that every episode that can be solved is.
        "vs_random": Preset(
            "vs_random",
            (WORLD_MODELS.default, RANDOM_ORDER_MODEL),
            (MEASURES.default,),
            (200,),
            conditions=("reset",),
            default_seeds=20,
            budget=WHOLE_SPACE,
            pretrain_pool=200,
        ),
        # Lifelong learning with the default model and measure: does the exploration of the
        # earlier scenarios (update) shorten the later ones against the pretraining set alone
        # (reset)? The whole candidate space as budget, 200 pretraining interactions.
        "lifelong": Preset(
            "lifelong",
            (WORLD_MODELS.default,),
            (MEASURES.default,),
            (200,),
            default_seeds=20,
            budget=WHOLE_SPACE,
            pretrain_pool=200,
        ),
        # Every world model under goal-directed from 200 pretraining interactions (reset), the
        # whole candidate space as budget: the evidence for the default model.
        "models": Preset(
            "models",
            PAPER_MODELS + OTHER_MODELS,
            (MEASURES.default,),
            (200,),
            conditions=("reset",),
            default_seeds=5,
            budget=WHOLE_SPACE,
            pretrain_pool=200,
        ),
        # The no-model baseline of the paper grid, at its budget: the random order uses no
        # training data, so 4 pretraining points stand for any number (`experiment report
        # --baseline-preset random` adds it to the paper grid's comparison).
        "random": Preset(
            "random",
            (RANDOM_ORDER_MODEL,),
            ("most-changes",),
            (4,),
            conditions=("reset",),
            default_seeds=20,
            budget=150,
            pretrain_pool=4,
        ),
        # Leave one family out: every shipped scenario (a novelty family) solved on its own
        # branch from 200 random pretraining interactions drawn from the sampler's catalog,
        # never from a scenario's scene (condition reset; `--with-others` adds the other
        # families' episodes first), by the default model and measure and by the random
        # order, paired by scene variant; the random order's cost per variant is the mean of
        # three of its permutations. See docs/experiments.md.
        "generalization": Preset(
            "generalization",
            (WORLD_MODELS.default, RANDOM_ORDER_MODEL),
            (MEASURES.default,),
            (200,),
            conditions=("reset",),
            default_seeds=10,
            budget=WHOLE_SPACE,
            pretrain_pool=200,
            scenarios=None,
            per_family=True,
            ordering=ORDERINGS.default,
            reach_check=True,
            random_draws=3,
        ),
        # Small enough for the test suite: 8 random interactions per seed, 5 exploration trials per episode.
        "smoke": Preset("smoke", ("nb",), ("most-changes",), (4,), default_seeds=2, budget=5, pretrain_pool=8),
    },
    default="paper",
)


def model_rank(model: str) -> tuple[int, str]:
    """Sort key putting models in the ``full`` preset's order, unknown ones after by name."""
    return rank_by(PRESETS["full"].models, model)


def measure_rank(measure: str) -> tuple[int, str]:
    """Sort key putting measures in the ``full`` preset's order (the paper's first)."""
    return rank_by(PRESETS["full"].measures, measure)


def get_preset(name: str) -> Preset:
    """The preset called ``name``, or an error listing the known ones."""
    return PRESETS.get_entry(name)


def validate_preset(preset: Preset) -> None:
    """Check a preset's model and measure names against the registries."""
    for model in preset.models:
        if model not in WORLD_MODELS:
            raise UnknownNameError("world model", model, tuple(WORLD_MODELS))
    for measure in preset.measures:
        if measure not in MEASURES:
            raise UnknownNameError("measure", measure, tuple(MEASURES))


def run_seeds(
    preset: Preset, *, seeds: int | Iterable[int] | None = None, first_seed: int = 0, variants: range | None = None
) -> tuple[int, ...]:
    """The seeds one run of ``preset`` takes.

    Args:
        seeds: a count (from ``first_seed``), explicit seeds, or None for the preset's default count.
        first_seed: where a count of seeds starts, so runners on several machines take disjoint seeds.
        variants: scene variants paired with the seeds: seed N solves variant N, so the
            variants choose the seeds and take the place of ``seeds`` and ``first_seed``.
    """
    if variants is not None:
        if seeds is not None or first_seed:
            raise LlcpsError(
                "--variants chooses the seeds itself (seed N solves variant N): drop --seeds and --first-seed",
                hint=f"e.g. `llcps experiment run --preset {preset.name} --variants 100:110`",
            )
        if variants.stop - 1 > MAX_SEED or len(variants) > MAX_SEEDS:
            raise LlcpsError(
                f"variants {variants.start}..{variants.stop - 1} cannot pair with seeds: at most {MAX_SEEDS} seeds up to {MAX_SEED}",
                hint="choose a smaller range",
            )
        return seed_list(variants)
    if seeds is not None and not isinstance(seeds, int):
        if first_seed:
            raise LlcpsError("a first seed goes with a count of seeds, not with explicit seeds")
        return seed_list(seeds)
    count = len(seed_list(preset.default_seeds if seeds is None else seeds))
    if first_seed + count - 1 > MAX_SEED:
        raise LlcpsError(
            f"seeds {first_seed}..{first_seed + count - 1} go beyond the largest seed {MAX_SEED}",
            hint="lower --first-seed or --seeds",
        )
    return tuple(range(first_seed, first_seed + count))
