"""The experiment grid: which sequences of scenarios an experiment runs, and their branches.

The paper's evaluation (Figure 2) crosses world model x measure x pretraining size x
condition, each *sequence* solving scenario1 -> scenario2 -> scenario3 in the novelty
condition. ``update`` lets the world model keep every trial across the sequence;
``reset`` sends the training data back to the pretraining set before each scenario.

Every sequence gets a deterministic branch name, so its trials stay inspectable and a
re-run can tell which sequences are complete. The name encodes the whole cell, and
:func:`parse_branch` reads it back: results are rebuilt from the store alone.

Names of world models and measures are plain strings here; :func:`validate_preset`
checks them against the registries in :mod:`llcps.models`. The paper's models and
measures, the longest branch name and the size of the candidate space each come from
the one place that defines them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterable

from llcps.cps.episode import DEFAULT_MEASURE, DEFAULT_MODEL
from llcps.errors import LlcpsError, UnknownNameError
from llcps.models.measures import PAPER_MEASURES
from llcps.models.registry import PAPER_MODELS
from llcps.store.tables import MAX_BRANCH_NAME

#: The order a sequence solves the scenarios in (the paper's order).
SCENARIO_SEQUENCE: tuple[str, ...] = ("scenario1", "scenario2", "scenario3")
#: ``update``: the world model keeps training across scenarios; ``reset``: the training
#: data goes back to the pretraining set before each scenario (a branch from that point).
EXPERIMENT_CONDITIONS: tuple[str, ...] = ("update", "reset")
#: 200 pretraining points ("Apriori Training") and 4 ("No Apriori Training").
PAPER_PRETRAIN_SIZES: tuple[int, ...] = (200, 4)

#: Prefix of every experiment branch; nothing else in a store starts with it.
BRANCH_PREFIX = "exp"
#: Separator of the fields of a branch name ("/" is not allowed in branch names).
SEP = "-"

# Preset and model names become single fields of a branch name, so they may not
# contain the separator; measures may (they are parsed as "whatever is left").
_FIELD = re.compile(r"^[a-z0-9_]+$")
_MEASURE = re.compile(r"^[a-z0-9_]+(-[a-z0-9_]+)*$")
_BRANCH_CHARS = re.compile(r"^[A-Za-z0-9_.:-]+$")


@dataclass(frozen=True, order=True)
class Cell:
    """One cell of the grid: a world model, a measure, a pretraining size and a condition."""

    model: str
    measure: str
    pretrain_size: int
    condition: str

    def __post_init__(self) -> None:
        if not _FIELD.match(self.model):
            raise LlcpsError(
                f"world model name {self.model!r} cannot name an experiment branch",
                hint="use lower-case letters, digits and '_' only",
            )
        if not _MEASURE.match(self.measure):
            raise LlcpsError(
                f"measure name {self.measure!r} cannot name an experiment branch",
                hint="use lower-case words joined by '-'",
            )
        if isinstance(self.pretrain_size, bool) or not isinstance(self.pretrain_size, int) or self.pretrain_size < 0:
            raise LlcpsError(f"pretraining size must be a non-negative integer, not {self.pretrain_size!r}")
        if self.condition not in EXPERIMENT_CONDITIONS:
            raise LlcpsError(
                f"unknown experiment condition {self.condition!r}",
                hint=f"choose one of: {', '.join(EXPERIMENT_CONDITIONS)}",
            )

    @property
    def label(self) -> str:
        """A short human label, e.g. ``nb / most-changes / p200 / update`` (``random order / p200 / reset``)."""
        return f"{cell_title(self.model, self.measure, self.pretrain_size)} / {self.condition}"


#: The model that ranks nothing: a seeded random order (the baseline every comparison uses).
RANDOM_ORDER_MODEL = "random"


def cell_title(model: str, measure: str, pretrain_size: int) -> str:
    """How tables and plots name a cell without its condition: ``nb / goal-directed / p200``.

    The random order ignores the measure (and its training data), so it is named for
    what it is: ``random order / p200``.
    """
    if model == RANDOM_ORDER_MODEL:
        return f"random order / p{pretrain_size}"
    return f"{model} / {measure} / p{pretrain_size}"


@dataclass(frozen=True, order=True)
class Sequence:
    """One run of :data:`SCENARIO_SEQUENCE` for one cell and one seed, on its own branch.

    ``variant`` is the scene variant every scenario of the sequence is solved in (0: the
    canonical scenes). A run over scene variants pairs them with seeds: seed N solves
    variant N (:meth:`Preset.sequences`), so each seed draws both its pretraining and its
    scenes, and update/reset or model/random stay paired by seed.
    """

    preset: str
    cell: Cell
    seed: int
    variant: int = 0

    def __post_init__(self) -> None:
        if not _FIELD.match(self.preset):
            raise LlcpsError(
                f"preset name {self.preset!r} cannot name an experiment branch",
                hint="use lower-case letters, digits and '_' only",
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise LlcpsError(f"seed must be a non-negative integer, not {self.seed!r}")
        if isinstance(self.variant, bool) or not isinstance(self.variant, int) or self.variant < 0:
            raise LlcpsError(f"variant must be a non-negative integer, not {self.variant!r}")
        # Fail at construction, not halfway through a run, if a name would be too long.
        longest = self.episode_branch(SCENARIO_SEQUENCE[-1])
        if len(longest) > MAX_BRANCH_NAME:
            raise LlcpsError(f"branch name {longest!r} is longer than {MAX_BRANCH_NAME} characters")

    @property
    def branch_name(self) -> str:
        """The sequence's branch, e.g. ``exp-paper-nb-most-changes-p200-update-s3``.

        A sequence on scene variant N > 0 ends in ``-vN`` (``...-update-s3-v3``); variant 0
        is the canonical scene, so its sequences keep the plain name.
        """
        c = self.cell
        fields = [BRANCH_PREFIX, self.preset, c.model, c.measure, f"p{c.pretrain_size}", c.condition, f"s{self.seed}"]
        if self.variant:
            fields.append(f"v{self.variant}")
        return SEP.join(fields)

    def episode_branch(self, scenario: str) -> str:
        """The branch one scenario of this sequence is solved on.

        Under ``update`` every scenario runs on the sequence branch, so each sees the
        trials of the ones before. Under ``reset`` each scenario gets its own branch
        forked from the pretraining point, so it sees the pretraining set only.
        """
        if scenario not in SCENARIO_SEQUENCE:
            raise UnknownNameError("scenario", scenario, SCENARIO_SEQUENCE)
        if self.cell.condition == "update":
            return self.branch_name
        return f"{self.branch_name}{SEP}{scenario}"

    @property
    def pretrain_branch(self) -> str:
        """The branch holding this seed's pretraining set, shared by every model and measure.

        Sharing it makes ``update`` and ``reset`` (and different models) at one seed start
        from identical data, which is what lets the statistics pair them by seed.
        """
        return pretrain_branch_name(self.preset, self.cell.pretrain_size, self.seed)


def pretrain_branch_name(preset: str, pretrain_size: int, seed: int) -> str:
    """Name of the pretraining branch of ``(preset, pretraining size, seed)``."""
    return SEP.join((BRANCH_PREFIX, preset, "pretrain", f"p{pretrain_size}", f"s{seed}"))


@dataclass(frozen=True)
class ParsedBranch:
    """What an experiment branch name says: its sequence and, for ``reset``, its scenario."""

    sequence: Sequence
    scenario: str | None


_TAIL = re.compile(
    r"^p(?P<pretrain>\d+)-(?P<condition>[a-z]+)-s(?P<seed>\d+)(?:-v(?P<variant>\d+))?(?:-(?P<scenario>[a-z0-9_]+))?$"
)


def parse_branch(name: str) -> ParsedBranch | None:
    """Read a branch name written by :class:`Sequence` back into its sequence.

    Returns ``None`` for any branch that is not an experiment sequence branch (the
    user's own branches, pretraining branches), so callers can filter a whole store.
    """
    parts = name.split(SEP, 3)
    if len(parts) != 4 or parts[0] != BRANCH_PREFIX or parts[2] == "pretrain":
        return None
    preset, model, rest = parts[1], parts[2], parts[3]
    # The measure may contain the separator; the tail after it has a fixed shape.
    match = None
    for m in re.finditer(r"-p\d+-", rest):
        candidate = _TAIL.match(rest[m.start() + 1 :])
        if candidate:
            match, measure = candidate, rest[: m.start()]
            break
    if match is None:
        return None
    scenario = match["scenario"]
    condition = match["condition"]
    if condition not in EXPERIMENT_CONDITIONS:
        return None
    if scenario is not None and (condition != "reset" or scenario not in SCENARIO_SEQUENCE):
        return None
    try:
        cell = Cell(model, measure, int(match["pretrain"]), condition)
        sequence = Sequence(preset, cell, int(match["seed"]), int(match["variant"] or 0))
    except LlcpsError:
        return None
    # Only names this module would write round-trip (no leading zeros, etc.).
    parsed = ParsedBranch(sequence, scenario)
    expected = sequence.branch_name if scenario is None else sequence.episode_branch(scenario)
    return parsed if expected == name else None


def is_valid_branch_name(name: str) -> bool:
    """The store's rules for branch names: no whitespace, no '..', no '/', bounded length."""
    return bool(_BRANCH_CHARS.match(name)) and ".." not in name and 0 < len(name) <= MAX_BRANCH_NAME


@dataclass(frozen=True)
class Preset:
    """A named grid: models x measures x pretraining sizes x conditions, and a default seed count."""

    name: str
    models: tuple[str, ...]
    measures: tuple[str, ...]
    pretrain_sizes: tuple[int, ...]
    conditions: tuple[str, ...] = EXPERIMENT_CONDITIONS
    default_seeds: int = 20
    #: Most exploration trials per episode (an unsolved episode records this many);
    #: None: the whole candidate space (:func:`llcps.cps.candidates.candidate_space_size`).
    budget: int | None = 150
    #: Random interactions drawn per seed; every pretraining set of the seed is this pool
    #: or a subset of it (the paper's 4 points are one per action from its 200).
    pretrain_pool: int = 200
    #: Exploration trials between refits of the world model within an episode.
    refit_every: int = 1

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

    def exploration_budget(self) -> int:
        """The budget as a number (None resolves to the size of the candidate space)."""
        if self.budget is not None:
            return self.budget
        from llcps.cps.candidates import candidate_space_size  # builds the scenarios' scenes

        return candidate_space_size()

    def cells(self) -> tuple[Cell, ...]:
        """Every cell, in a fixed order (model, measure, pretraining size, condition)."""
        return tuple(
            Cell(model, measure, size, condition)
            for model in self.models
            for measure in self.measures
            for size in self.pretrain_sizes
            for condition in self.conditions
        )

    def sequences(self, seeds: int | Iterable[int] | None = None, *, variants: bool = False) -> tuple[Sequence, ...]:
        """Every sequence of the grid; seeds grouped outermost so a partial run covers all cells.

        Args:
            seeds: a count ``n`` (seeds ``0..n-1``), explicit seeds, or ``None`` for the default count.
            variants: solve seed N's scenarios in scene variant N (paired, not crossed:
                one variant per seed); otherwise every seed uses the canonical scenes.
        """
        chosen = _seed_list(self.default_seeds if seeds is None else seeds)
        return tuple(
            Sequence(self.name, cell, seed, seed if variants else 0) for seed in chosen for cell in self.cells()
        )


def _seed_list(seeds: int | Iterable[int]) -> tuple[int, ...]:
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


_EXTRA_MODELS = ("random", "logreg", "forest")

#: A budget larger than any scenario's candidate space: the episode ends when every
#: candidate was tried (an unsolved episode records how many there were).
WHOLE_SPACE = 100_000

#: Exploration trials between world-model refits in the paper's grids. The paper updates
#: its models during exploration without saying how often; refitting the network after
#: every trial would make it 80 % of a grid's cost (0.6 s a refit at 200-500 trials).
GRID_REFIT_EVERY = 10

PRESETS: dict[str, Preset] = {
    "paper": Preset(
        "paper", PAPER_MODELS, PAPER_MEASURES, PAPER_PRETRAIN_SIZES, default_seeds=20, refit_every=GRID_REFIT_EVERY
    ),
    "full": Preset(
        "full",
        PAPER_MODELS + _EXTRA_MODELS,
        PAPER_MEASURES + ("goal-directed",),
        PAPER_PRETRAIN_SIZES,
        default_seeds=20,
        refit_every=GRID_REFIT_EVERY,
    ),
    # Model-guided exploration against no model, scenario by scenario: each episode starts
    # from the seed's 200 random pretraining interactions (condition reset), with the
    # whole candidate space as budget so that every episode that can be solved is.
    "vs_random": Preset(
        "vs_random",
        (DEFAULT_MODEL, "random"),
        (DEFAULT_MEASURE,),
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
        (DEFAULT_MODEL,),
        (DEFAULT_MEASURE,),
        (200,),
        default_seeds=20,
        budget=WHOLE_SPACE,
        pretrain_pool=200,
    ),
    # Every world model under goal-directed from 200 pretraining interactions (reset), the
    # whole candidate space as budget: the evidence for the default model.
    "models": Preset(
        "models",
        PAPER_MODELS + _EXTRA_MODELS,
        (DEFAULT_MEASURE,),
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
        "random", ("random",), ("most-changes",), (4,), conditions=("reset",), default_seeds=20, budget=150, pretrain_pool=4
    ),
    # Small enough for the test suite: 8 random interactions per seed, 5 exploration trials per episode.
    "smoke": Preset("smoke", ("nb",), ("most-changes",), (4,), default_seeds=2, budget=5, pretrain_pool=8),
}


def _rank(order: tuple[str, ...], name: str) -> tuple[int, str]:
    return (order.index(name), "") if name in order else (len(order), name)


def model_rank(model: str) -> tuple[int, str]:
    """Sort key putting models in the ``full`` preset's order, unknown ones after by name."""
    return _rank(PRESETS["full"].models, model)


def measure_rank(measure: str) -> tuple[int, str]:
    """Sort key putting measures in the ``full`` preset's order (the paper's first)."""
    return _rank(PRESETS["full"].measures, measure)


def scenario_rank(scenario: str) -> tuple[int, str]:
    """Sort key following :data:`SCENARIO_SEQUENCE`."""
    return _rank(SCENARIO_SEQUENCE, scenario)


def condition_rank(condition: str) -> tuple[int, str]:
    """Sort key putting ``update`` before ``reset``."""
    return _rank(EXPERIMENT_CONDITIONS, condition)


def get_preset(name: str) -> Preset:
    """The preset called ``name``, or an error listing the known ones."""
    try:
        return PRESETS[name]
    except KeyError:
        raise UnknownNameError("preset", name, tuple(PRESETS)) from None


def validate_preset(preset: Preset) -> None:
    """Check a preset's model and measure names against the registries.

    Imports :mod:`llcps.models` only here, so reading results never pays for torch.
    """
    from llcps.models import WORLD_MODELS
    from llcps.models.measures import MEASURES

    for model in preset.models:
        if model not in WORLD_MODELS:
            raise UnknownNameError("world model", model, tuple(WORLD_MODELS))
    for measure in preset.measures:
        if measure not in MEASURES:
            raise UnknownNameError("measure", measure, tuple(MEASURES))
