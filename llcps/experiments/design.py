"""The experimental design: cells, sequences and the branch names they run on.

The paper's evaluation (Figure 2) crosses world model x measure x pretraining size x
condition, each *sequence* solving scenario1 -> scenario2 -> scenario3 in the novelty
condition; a preset (or ``experiment run --scenarios``) may solve any list of scenarios
instead. ``update`` lets the world model keep every trial across the sequence;
``reset`` sends the training data back to the pretraining set before each scenario;
``others`` solves each scenario on its own branch from the pretraining set after every
*other* scenario of the list (leave-one-out with experience of the rest).

Every sequence gets a deterministic branch name, so its trials stay inspectable and a
re-run can tell which sequences are complete. The name encodes the whole cell, and
:func:`parse_branch` reads it back: results are rebuilt from the store alone. Which
cells a run crosses is a preset's choice (:mod:`llcps.experiments.presets`).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field

from llcps.errors import LlcpsError
from llcps.store.tables import MAX_BRANCH_NAME

#: The paper's scenarios in the order its sequences solve them: the default list of the
#: paper's presets, and the order reports sort scenarios in (others come after, by name).
PAPER_SCENARIOS: tuple[str, ...] = ("scenario1", "scenario2", "scenario3")
#: ``update``: the world model keeps training across scenarios; ``reset``: the training
#: data goes back to the pretraining set before each scenario (a branch from that point);
#: ``others``: like reset, but each scenario's branch first solves every other scenario
#: of the list (in the list's order), so the held-out one sees the others' trials.
EXPERIMENT_CONDITIONS: tuple[str, ...] = ("update", "reset", "others")
#: The paper's two conditions (Figure 2): every grid's default.
PAPER_CONDITIONS: tuple[str, ...] = ("update", "reset")
#: The conditions that solve each scenario on its own branch (named after the scenario).
OWN_BRANCH_CONDITIONS: tuple[str, ...] = ("reset", "others")

#: Most repeats (draws) of one sequence a grid may ask for: draws are numbered 0..MAX_DRAWS-1.
MAX_DRAWS = 100

#: Prefix of every experiment branch; nothing else in a store starts with it.
BRANCH_PREFIX = "exp"
#: Separator of the fields of a branch name ("/" is not allowed in branch names).
SEP = "-"

# Preset and model names become single fields of a branch name, so they may not
# contain the separator; measures may (they are parsed as "whatever is left").
_FIELD = re.compile(r"^[a-z0-9_]+$")
_MEASURE = re.compile(r"^[a-z0-9_]+(-[a-z0-9_]+)*$")
_BRANCH_CHARS = re.compile(r"^[A-Za-z0-9_.:-]+$")
# A scenario's name is the last field of an episode branch: a PDDL-like name that cannot
# be read as the variant or the draw field (``v3``, ``d2``).
_SCENARIO = re.compile(r"^[a-z][a-z0-9_]*$")
_NUMBERED_FIELD = re.compile(r"^[vd]\d+$")


def check_scenario_name(name: str) -> str:
    """``name`` if it can end an experiment branch, else an error saying why."""
    if not _SCENARIO.match(name) or _NUMBERED_FIELD.match(name):
        raise LlcpsError(
            f"scenario name {name!r} cannot name an experiment branch",
            hint="use lower-case letters, digits and '_', starting with a letter (not v<digits> or d<digits>)",
        )
    return name


def draw_seed(seed: int, draw: int) -> int:
    """The world model's seed of draw ``draw`` > 0 of a sequence at ``seed``: 32 bits of a
    hash of both, so each draw of the random order is another permutation of the same
    episode (draw 0 is the sequence's own seed)."""
    digest = hashlib.blake2b(f"llcps-draw:{seed}:{draw}".encode(), digest_size=4).digest()
    return int.from_bytes(digest, "little")


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


def explores_in(model: str, ordering: str) -> str:
    """The ordering episodes of ``model`` explore in when ``ordering`` is asked for: the
    random order always in the paper's, so that one set of random-order episodes is the
    baseline of every ordering, whatever a preset or a life explores in."""
    from llcps.cps.orderings import PAPER_ORDERING

    return PAPER_ORDERING if model == RANDOM_ORDER_MODEL else ordering


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
    """One run of a list of scenarios for one cell and one seed, on its own branch.

    ``scenarios`` (the paper's three unless a preset or ``--scenarios`` says otherwise)
    is what the sequence solves, in order. It is not part of the sequence's identity:
    the branch names do not encode it, and results read back from the store know each
    episode's scenario from the episode itself.

    ``variant`` is the scene variant every scenario of the sequence is solved in (0: the
    canonical scenes). A run over scene variants pairs them with seeds: seed N solves
    variant N (:meth:`~llcps.experiments.presets.Preset.sequences`), so each seed draws both its pretraining and its
    scenes, and update/reset or model/random stay paired by seed.

    ``draw`` numbers repeats of one sequence that differ only in the world model's seed
    (:attr:`model_seed`): the random order's further permutations of the same episodes,
    which the ``generalization`` preset averages (0: the sequence itself).
    """

    preset: str
    cell: Cell
    seed: int
    variant: int = 0
    scenarios: tuple[str, ...] = field(default=PAPER_SCENARIOS, compare=False)
    draw: int = 0

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
        if isinstance(self.draw, bool) or not isinstance(self.draw, int) or not 0 <= self.draw < MAX_DRAWS:
            raise LlcpsError(f"draw must be an integer from 0 to {MAX_DRAWS - 1}, not {self.draw!r}")
        if not self.scenarios or len(set(self.scenarios)) != len(self.scenarios):
            raise LlcpsError(f"a sequence needs distinct scenarios, not {self.scenarios!r}")
        # Fail at construction, not halfway through a run, if a name would be too long.
        for scenario in self.scenarios:
            branch = self.episode_branch(scenario)
            if len(branch) > MAX_BRANCH_NAME:
                raise LlcpsError(f"branch name {branch!r} is longer than {MAX_BRANCH_NAME} characters")

    @property
    def branch_name(self) -> str:
        """The sequence's branch, e.g. ``exp-paper-nb-most-changes-p200-update-s3``.

        A sequence on scene variant N > 0 ends in ``-vN`` (``...-update-s3-v3``); variant 0
        is the canonical scene, so its sequences keep the plain name. Draw D > 0 adds
        ``-dD`` after them (``...-reset-s3-v3-d1``).
        """
        c = self.cell
        fields = [BRANCH_PREFIX, self.preset, c.model, c.measure, f"p{c.pretrain_size}", c.condition, f"s{self.seed}"]
        if self.variant:
            fields.append(f"v{self.variant}")
        if self.draw:
            fields.append(f"d{self.draw}")
        return SEP.join(fields)

    @property
    def model_seed(self) -> int | None:
        """The world model's seed when it is not the sequence's (a draw > 0), else None."""
        return draw_seed(self.seed, self.draw) if self.draw else None

    def episode_branch(self, scenario: str) -> str:
        """The branch one scenario of this sequence is solved on.

        Under ``update`` every scenario runs on the sequence branch, so each sees the
        trials of the ones before. Under ``reset`` each scenario gets its own branch
        forked from the pretraining point, so it sees the pretraining set only; under
        ``others`` that branch also holds the episodes of the list's other scenarios,
        solved on it first.
        """
        check_scenario_name(scenario)
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
    """What an experiment branch name says: its sequence and, for ``reset`` and ``others``, its scenario."""

    sequence: Sequence
    scenario: str | None


_TAIL = re.compile(
    r"^p(?P<pretrain>\d+)-(?P<condition>[a-z]+)-s(?P<seed>\d+)(?:-v(?P<variant>\d+))?(?:-d(?P<draw>\d+))?"
    r"(?:-(?P<scenario>[a-z0-9_]+))?$"
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
    if scenario is not None and condition not in OWN_BRANCH_CONDITIONS:
        return None
    try:
        cell = Cell(model, measure, int(match["pretrain"]), condition)
        sequence = Sequence(preset, cell, int(match["seed"]), int(match["variant"] or 0), draw=int(match["draw"] or 0))
        # Only names this module would write round-trip (no leading zeros, etc.).
        expected = sequence.branch_name if scenario is None else sequence.episode_branch(scenario)
    except LlcpsError:
        return None
    parsed = ParsedBranch(sequence, scenario)
    return parsed if expected == name else None


def is_valid_branch_name(name: str) -> bool:
    """The store's rules for branch names: no whitespace, no '..', no '/', bounded length."""
    return bool(_BRANCH_CHARS.match(name)) and ".." not in name and 0 < len(name) <= MAX_BRANCH_NAME


def rank_by(order: tuple[str, ...], name: str) -> tuple[int, str]:
    """Sort key: the position of ``name`` in ``order``; names not in it come after, by name."""
    return (order.index(name), "") if name in order else (len(order), name)


def scenario_rank(scenario: str) -> tuple[int, str]:
    """Sort key: the paper's scenarios in the paper's order, then any others by name."""
    return rank_by(PAPER_SCENARIOS, scenario)


def condition_rank(condition: str) -> tuple[int, str]:
    """Sort key putting ``update`` before ``reset``."""
    return rank_by(EXPERIMENT_CONDITIONS, condition)
