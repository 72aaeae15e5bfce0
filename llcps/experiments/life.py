"""Lives: a lifelong benchmark as data, in which novelty families recur.

A *life* is a sequence of K episodes drawn from a list of novelty families (scenarios):
the next episode is a recurrence of an already-met family with probability
``p_recur``, otherwise a family not met yet. *Probe* families are held back until the
last quarter of the life, where their first encounters are mixed among recurrences.
A life file (TOML, checked by pydantic) declares the families, K, ``p_recur``, the
probes, the share of episodes solved in the original condition, how variants are
drawn, the pretraining and the conditions the life is run under. ``llcps life show
default`` prints a shipped one; docs/experiments.md describes every field.

Life number N draws its episodes from seed N (:func:`draw_life`): the family order,
the probes, the variants and the original-condition episodes. Every condition of
life N solves that same list (paired lives), each on its own branches:

- ``update``: the world model and K' carry over from episode to episode (one branch);
- ``reset``: every episode from the pretraining point (a branch per episode);
- ``scratch``: like ``update``, without pretraining;
- ``random``: like ``update``, exploring in a random order (the ``random`` model);
- an exploration ordering's name (``ranked``, ``hedged``, ...): like ``update``,
  exploring in that ordering, so every ordering runs as a condition.

After the life, the conditions that carry experience over re-solve a fresh variant of
every family met, and its original condition, each on a fork of the life's end
(forgetting).
"""

from __future__ import annotations

import functools
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from llcps.errors import LlcpsError, UnknownNameError
from llcps.experiments.design import RANDOM_ORDER_MODEL, check_scenario_name, explores_in
from llcps.registry import Registry

#: Where the shipped life files are.
SHIPPED_DIR = Path(__file__).with_name("lives")
#: Prefix of every life branch; nothing else in a store starts with it.
LIFE_PREFIX = "life"
#: Most episodes a life may have, and most lives one run may ask for.
MAX_EPISODES = 1000
MAX_LIVES = 10_000
#: Largest bytes of a life file read.
MAX_FILE_BYTES = 64 * 1024
#: The budget that means "the whole candidate space" (as the ``lifelong`` preset's).
WHOLE = "whole"
#: Stream tag of a life's draws (kept apart from every other use of the seed).
_LIFE_STREAM = 0x11FE
_FIELD = re.compile(r"^[a-z][a-z0-9_]*$")


@dataclass(frozen=True)
class LifeCondition:
    """How a condition solves a life's episodes.

    Attributes:
        carry: ``update`` (one branch, experience carries over) or ``reset`` (each
            episode from the pretraining point, on its own branch).
        pretrained: whether the life starts from the pretraining set (else from nothing).
        model: the world model (None: the life file's).
        ordering: the exploration ordering (None: the solver's default).
    """

    name: str
    carry: Literal["update", "reset"]
    pretrained: bool = True
    model: str | None = None
    ordering: str | None = None
    description: str = ""

    @property
    def forgets(self) -> bool:
        """Whether the life's end differs from its start, so forgetting is measured."""
        return self.carry == "update"


LIFE_CONDITIONS: Registry[LifeCondition] = Registry(
    "life condition",
    {
        "update": LifeCondition("update", "update", description="the world model and K' carry over"),
        "reset": LifeCondition("reset", "reset", description="every episode from the pretraining point"),
        "scratch": LifeCondition("scratch", "update", pretrained=False, description="update without pretraining"),
        "random": LifeCondition("random", "update", model=RANDOM_ORDER_MODEL, description="update, exploring in a random order"),
    },
    default="update",
)


def life_condition(name: str) -> LifeCondition:
    """The condition called ``name``: one of :data:`LIFE_CONDITIONS`, or an exploration
    ordering's name (:data:`~llcps.cps.orderings.ORDERINGS`) with '_' for '-' (a
    condition names branches), which is ``update`` exploring in that ordering, so every
    ordering (a baseline among them) runs as a condition: ``case_based`` is ``case-based``."""
    if name in LIFE_CONDITIONS:
        return LIFE_CONDITIONS[name]
    ordering = _orderings_by_condition().get(name)
    if ordering is not None:
        return LifeCondition(name, "update", ordering=ordering, description=f"update, exploring in the {ordering} ordering")
    raise UnknownNameError("life condition", name, condition_names())


def _orderings_by_condition() -> dict[str, str]:
    from llcps.cps.orderings import ORDERINGS

    return {n.replace("-", "_"): n for n in ORDERINGS if _FIELD.match(n.replace("-", "_"))}


def condition_names() -> tuple[str, ...]:
    """Every name :func:`life_condition` accepts: the conditions, then the orderings."""
    return tuple(dict.fromkeys((*LIFE_CONDITIONS, *_orderings_by_condition())))


@functools.cache
def _schema() -> Any:
    """The pydantic model of a life file (built on first use: pydantic is not loaded where the CLI starts)."""
    from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

    class Variants(BaseModel):
        model_config = ConfigDict(extra="forbid")
        #: ``canonical``: every episode in variant 0; ``life``: life N in variant N
        #: (the ``--variants`` of a preset); ``random``: each episode draws one from ``range``.
        draw: Literal["canonical", "life", "random"] = "random"
        #: ``[low, high)`` the random draws and the forgetting re-solves take variants from.
        range: tuple[int, int] = (5000, 6000)

        @field_validator("range")
        @classmethod
        def _range(cls, value: tuple[int, int]) -> tuple[int, int]:
            low, high = value
            if not 0 <= low < high <= 2**32:
                raise ValueError(f"must be [low, high) with 0 <= low < high <= 2**32, got [{low}, {high}]")
            return value

    class Pretraining(BaseModel):
        model_config = ConfigDict(extra="forbid")
        #: Random interactions before the life (from the sampler's catalog, never a family's scene).
        count: int = Field(200, ge=1, le=100_000)
        #: ``life``: life N pretrains with seed N; a number: every life shares that pretraining.
        seed: Literal["life"] | int = "life"

        @field_validator("seed")
        @classmethod
        def _seed(cls, value: Any) -> Any:
            if isinstance(value, int) and not 0 <= value <= 2**32 - 1:
                raise ValueError("must be 'life' or a seed from 0 to 2**32-1")
            return value

    class LifeModel(BaseModel):
        model_config = ConfigDict(extra="forbid")
        name: str
        description: str = ""
        #: Scenario names, aliases or .toml paths; empty: every shipped scenario.
        families: list[str] = Field(default_factory=list)
        #: ``random``: new families come in a random order; ``listed``: in the file's order.
        order: Literal["random", "listed"] = "random"
        episodes: int = Field(ge=1, le=MAX_EPISODES)
        p_recur: float = Field(ge=0.0, le=1.0)
        #: A number of families drawn per life, or the families themselves.
        probes: int | list[str] = 0
        #: Share of recurrences solved in the original condition (the plan works: 0 exploration).
        original_share: float = Field(0.0, ge=0.0, le=1.0)
        conditions: list[str] = Field(default_factory=lambda: ["update", "reset"])
        #: Most exploration trials per episode, or ``whole`` (the whole candidate space).
        budget: Literal["whole"] | int = WHOLE
        #: The AUC's horizon tau (None: the budget, or the candidate space for ``whole``).
        tau: int | None = Field(None, ge=1)
        refit_every: int = Field(1, ge=1, le=100_000)
        model: str | None = None
        measure: str | None = None
        #: The exploration ordering (None: the registry's default); a condition named after
        #: an ordering explores in that one instead.
        ordering: str | None = None
        #: Try last the candidates the arm would refuse (False: the paper's agent).
        reach_check: bool = True
        #: Episodes in the last-m window of the novelty reaction (None: the last quarter).
        last: int | None = Field(None, ge=1)
        #: Re-solve every met family after the life (fresh variant and original condition).
        forgetting: bool = True
        variants: Variants = Field(default_factory=Variants)
        pretraining: Pretraining = Field(default_factory=Pretraining)

        @field_validator("name")
        @classmethod
        def _name(cls, value: str) -> str:
            if not _FIELD.match(value) or len(value) > 24:
                raise ValueError("must be lower-case letters, digits and '_', starting with a letter, at most 24 characters")
            return value

        @field_validator("budget")
        @classmethod
        def _budget(cls, value: Any) -> Any:
            if isinstance(value, int) and not 0 <= value <= 100_000:
                raise ValueError("must be 'whole' or a number from 0 to 100000")
            return value

        @field_validator("conditions")
        @classmethod
        def _conditions(cls, value: list[str]) -> list[str]:
            if not value:
                raise ValueError("name at least one condition")
            for name in value:
                if name not in condition_names():
                    raise ValueError(f"unknown condition {name!r}: choose from {', '.join(condition_names())}")
            if len(set(value)) != len(value):
                raise ValueError("a condition is named twice")
            return value

        @model_validator(mode="after")
        def _probes(self) -> Any:
            if isinstance(self.probes, int) and self.probes < 0:
                raise ValueError("probes: must be a count of 0 or more, or a list of families")
            return self

    return LifeModel


@dataclass(frozen=True)
class Life:
    """A checked life file: what :func:`draw_life` and a run need.

    ``families`` are ``(name, source)`` pairs: the name, and what a worker passes to
    ``get_scenario`` (the name, or a .toml file's absolute path).
    """

    name: str
    families: tuple[tuple[str, str], ...]
    episodes: int
    p_recur: float
    probes: int | tuple[str, ...]
    order: str = "random"
    original_share: float = 0.0
    conditions: tuple[str, ...] = ("update", "reset")
    budget: int | None = None  # None: the whole candidate space
    tau: int | None = None
    refit_every: int = 1
    model: str | None = None
    measure: str | None = None
    ordering: str | None = None
    reach_check: bool = True
    last: int | None = None
    forgetting: bool = True
    variant_draw: str = "random"
    variant_range: tuple[int, int] = (5000, 6000)
    pretrain_count: int = 200
    pretrain_seed: int | None = None  # None: the life's own seed
    description: str = ""
    source: str = ""
    text: str = field(default="", compare=False, repr=False)
    #: The length the draws were made for when cut short by ``--episodes`` (None: ``episodes``).
    cut_from: int | None = None

    @property
    def family_names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.families)

    def source_of(self, family: str) -> str:
        return dict(self.families)[family]

    def with_episodes(self, episodes: int | None) -> Life:
        """This life cut to ``episodes`` (None: unchanged); the draws of the kept episodes do not change."""
        if episodes is None or episodes == self.episodes:
            return self
        if isinstance(episodes, bool) or not isinstance(episodes, int) or not 1 <= episodes <= self.episodes:
            raise LlcpsError(
                f"--episodes must be from 1 to the life's {self.episodes}, not {episodes!r}",
                hint="--episodes cuts a life short for a quick look",
            )
        return replace(self, episodes=episodes, cut_from=_cut_from(self))

    def with_conditions(self, conditions: list[str] | tuple[str, ...] | None) -> Life:
        """This life under ``conditions`` instead of its file's (None: unchanged)."""
        if conditions is None:
            return self
        chosen = tuple(dict.fromkeys(c.strip() for c in conditions))
        if not chosen:
            raise LlcpsError("name at least one condition", hint=f"choose from {', '.join(LIFE_CONDITIONS)}")
        for name in chosen:
            life_condition(name)
        return replace(self, conditions=chosen)

    def model_for(self, condition: LifeCondition) -> str:
        from llcps.models.registry import WORLD_MODELS

        return condition.model or self.model or WORLD_MODELS.default

    def ordering_for(self, condition: LifeCondition) -> str:
        from llcps.cps.orderings import ORDERINGS

        return explores_in(self.model_for(condition), condition.ordering or self.ordering or ORDERINGS.default)

    def measure_name(self) -> str:
        from llcps.models.measures import MEASURES

        return self.measure or MEASURES.default

    def solve_budget(self) -> int:
        """The budget each episode solves with (``whole``: the ``lifelong`` preset's whole-space budget)."""
        from llcps.experiments.presets import WHOLE_SPACE

        return WHOLE_SPACE if self.budget is None else self.budget

    def horizon(self) -> int:
        """tau of the AUC: the file's, else the budget, else the whole candidate space."""
        if self.tau is not None:
            return self.tau
        if self.budget is not None:
            return max(1, self.budget)
        from llcps.cps.candidates import candidate_space_size

        return candidate_space_size()


def _cut_from(life: Life) -> int:
    return life.cut_from or life.episodes


@dataclass(frozen=True)
class LifeEpisode:
    """One episode of a life: its index (0-based), family, variant and condition."""

    index: int
    family: str
    variant: int
    condition: str = "novelty"
    first_encounter: bool = False
    probe: bool = False


@dataclass(frozen=True)
class LifeDraw:
    """What life number ``seed`` solves: its episodes, its probes and the forgetting re-solves."""

    seed: int
    episodes: tuple[LifeEpisode, ...]
    probes: tuple[str, ...]
    #: (family, fresh variant) per family met, in order of first encounter.
    after: tuple[tuple[str, int], ...] = ()


def draw_life(life: Life, seed: int) -> LifeDraw:
    """The episodes of life number ``seed``: the same for every condition, bit for bit.

    Draws, from one generator seeded by ``seed``: the probes (when the file gives a
    count), the positions of the probes' first encounters (distinct, in the last
    quarter), then episode by episode: a recurrence with probability ``p_recur`` (a
    met family, uniformly) unless no family is met, else a new family (a random
    unmet non-probe one, or the next in the file's order for ``order = "listed"``),
    a recurrence anyway once every non-probe family is met; its variant; and for a
    recurrence, the original condition with probability ``original_share``. A life
    cut short (``--episodes``) is the first K episodes of the whole one.
    """
    import numpy as np

    rng = np.random.default_rng([int(seed), _LIFE_STREAM])
    length = _cut_from(life)
    names = life.family_names
    if isinstance(life.probes, int):
        probes = tuple(sorted(rng.choice(names, size=life.probes, replace=False).tolist())) if life.probes else ()
    else:
        probes = tuple(life.probes)
    quarter = max(1, length // 4) if probes else 0
    slots = sorted(rng.choice(np.arange(length - quarter, length), size=len(probes), replace=False).tolist()) if probes else []
    probe_at = dict(zip(slots, rng.permutation(np.array(probes, dtype=object)).tolist())) if probes else {}
    regular = [n for n in names if n not in probes]
    met: list[str] = []
    used: dict[str, set[int]] = {n: set() for n in names}
    episodes: list[LifeEpisode] = []
    low, high = life.variant_range
    for index in range(length):
        new = [n for n in regular if n not in met]
        recur = rng.random() < life.p_recur
        if index in probe_at:
            family = probe_at[index]
        elif met and (recur or not new):
            family = met[int(rng.integers(len(met)))]
        else:  # a new family (there is one: the probes leave at least one family out)
            family = new[0] if life.order == "listed" else new[int(rng.integers(len(new)))]
        first = family not in met
        if life.variant_draw == "canonical":
            variant = 0
        elif life.variant_draw == "life":
            variant = int(seed)
        else:
            variant = int(rng.integers(low, high))
        original = not first and rng.random() < life.original_share
        if first:
            met.append(family)
        used[family].add(variant)
        episodes.append(LifeEpisode(index, family, variant, "original" if original else "novelty", first, family in probes))
    after: list[tuple[str, int]] = []
    for family in met if life.forgetting else ():
        fresh = int(rng.integers(low, high))
        while fresh in used[family]:
            fresh = low + (fresh - low + 1) % (high - low)
        after.append((family, fresh))
    kept = tuple(episodes[: life.episodes])
    kept_families = list(dict.fromkeys(e.family for e in kept))
    return LifeDraw(int(seed), kept, probes, tuple(a for a in after if a[0] in kept_families))


# --- branch names -------------------------------------------------------------------


def life_branch(life: str, condition: str, seed: int) -> str:
    """The branch of life ``seed`` under ``condition``, e.g. ``life-default-update-l3``."""
    return f"{LIFE_PREFIX}-{life}-{condition}-l{seed}"


def episode_branch(life: str, condition: LifeCondition, seed: int, index: int) -> str:
    """Where episode ``index`` is solved: the life's branch, or under ``reset`` its own fork."""
    base = life_branch(life, condition.name, seed)
    return base if condition.carry == "update" else f"{base}-e{index}"


def after_branch(life: str, condition: str, seed: int, family: str, episode_condition: str) -> str:
    """The fork of the life's end on which ``family`` is re-solved after the life."""
    suffix = "" if episode_condition == "novelty" else "-original"
    return f"{life_branch(life, condition, seed)}-after-{family}{suffix}"


def pretrain_branch(life: Life, seed: int) -> str:
    """The branch of life ``seed``'s pretraining set, shared by its conditions."""
    from llcps.experiments.design import pretrain_branch_name

    return pretrain_branch_name(pretrain_preset(life), life.pretrain_count, pretrain_seed(life, seed))


def pretrain_preset(life: Life) -> str:
    """The preset field of a life's pretraining branches (``life_<name>``)."""
    return f"{LIFE_PREFIX}_{life.name}"


def pretrain_seed(life: Life, seed: int) -> int:
    return seed if life.pretrain_seed is None else life.pretrain_seed


_BRANCH = re.compile(r"^life-(?P<life>[a-z][a-z0-9_]*)-(?P<condition>[a-z][a-z0-9_]*)-l(?P<seed>\d+)(?P<rest>-.*)?$")


def parse_life_branch(name: str) -> tuple[str, str, int] | None:
    """``(life, condition, seed)`` of a branch a life run wrote, else None."""
    match = _BRANCH.match(name)
    if match is None:
        return None
    return match["life"], match["condition"], int(match["seed"])


# --- reading life files -------------------------------------------------------------


def shipped_lives() -> dict[str, Path]:
    """name -> file of every shipped life, by file name."""
    return {path.stem: path for path in sorted(SHIPPED_DIR.glob("*.toml"))}


def is_life_path(name: str) -> bool:
    return name.endswith(".toml") or "/" in name


def load_life(name: str) -> Life:
    """A shipped life by name, or a life file by path; errors name the file and field (exit 2)."""
    shipped = shipped_lives()
    if name in shipped:
        path = shipped[name]
    elif is_life_path(name):
        path = Path(name)
    else:
        raise UnknownNameError("life", name, tuple(shipped) + ("or a path to a .toml file",))
    where = str(path)
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise LlcpsError(f"cannot read life file {where}: {exc.strerror or exc}", hint="check the path") from None
    if len(raw) > MAX_FILE_BYTES:
        raise LlcpsError(f"{where}: larger than {MAX_FILE_BYTES // 1024} KiB", hint="a life file is a few lines")
    try:
        text = raw.decode("utf-8")
        data = tomllib.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise LlcpsError(f"{where}: not a TOML file: {exc}", hint="see `llcps life show default` for a working file") from None
    return life_from_data(where, data, text=text)


def life_from_data(where: str, data: dict[str, Any], *, text: str = "") -> Life:
    """A parsed life file as a :class:`Life`, or one error naming the file and field."""
    from pydantic import ValidationError

    from llcps.scenarios.file_format import validation_error

    try:
        model = _schema().model_validate(data)
    except ValidationError as exc:
        raise _life_error(validation_error(where, exc)) from None
    families = _families(where, model.families)
    names = [n for n, _ in families]
    if isinstance(model.probes, list):
        for probe in model.probes:
            if probe not in names:
                raise _field_error(where, "probes", f"{probe!r} is not one of the life's families ({', '.join(names)})")
        if len(set(model.probes)) != len(model.probes):
            raise _field_error(where, "probes", "a family is named twice")
        probes: int | tuple[str, ...] = tuple(model.probes)
        count = len(probes)
    else:
        probes = count = model.probes
    if count >= len(names) and count:
        raise _field_error(where, "probes", f"{count} probe(s) leave none of the {len(names)} families for the life's start")
    if count > max(1, model.episodes // 4):
        raise _field_error(where, "probes", f"{count} probes do not fit in the last quarter of {model.episodes} episodes")
    from llcps.models.measures import MEASURES
    from llcps.models.registry import WORLD_MODELS

    if model.model is not None and model.model not in WORLD_MODELS:
        raise _field_error(where, "model", f"unknown world model {model.model!r}: choose from {', '.join(WORLD_MODELS)}")
    if model.measure is not None and model.measure not in MEASURES:
        raise _field_error(where, "measure", f"unknown measure {model.measure!r}: choose from {', '.join(MEASURES)}")
    from llcps.cps.orderings import ORDERINGS

    if model.ordering is not None and model.ordering not in ORDERINGS:
        raise _field_error(where, "ordering", f"unknown ordering {model.ordering!r}: choose from {', '.join(ORDERINGS)}")
    return Life(
        name=model.name,
        families=families,
        episodes=model.episodes,
        p_recur=model.p_recur,
        probes=probes,
        order=model.order,
        original_share=model.original_share,
        conditions=tuple(model.conditions),
        budget=None if model.budget == WHOLE else int(model.budget),
        tau=model.tau,
        refit_every=model.refit_every,
        model=model.model,
        measure=model.measure,
        ordering=model.ordering,
        reach_check=model.reach_check,
        last=model.last,
        forgetting=model.forgetting,
        variant_draw=model.variants.draw,
        variant_range=tuple(model.variants.range),
        pretrain_count=model.pretraining.count,
        pretrain_seed=None if model.pretraining.seed == "life" else int(model.pretraining.seed),
        description=model.description,
        source=where,
        text=text,
    )


def _families(where: str, families: list[str]) -> tuple[tuple[str, str], ...]:
    from llcps.experiments.presets import resolve_scenarios

    try:
        resolved = resolve_scenarios(families or None)
    except LlcpsError as exc:
        raise LlcpsError(f"{where}: families: {exc.message}", hint=exc.hint) from None
    for name, _ in resolved:
        check_scenario_name(name)
    return resolved


def _field_error(where: str, field_name: str, message: str) -> LlcpsError:
    return LlcpsError(f"{where}: {field_name}: {message}", hint="see the life file format in docs/experiments.md")


def _life_error(error: LlcpsError) -> LlcpsError:
    return LlcpsError(error.message, hint="see the life file format in docs/experiments.md, or `llcps life show default`")


__all__ = [
    "LIFE_CONDITIONS",
    "LIFE_PREFIX",
    "Life",
    "LifeCondition",
    "LifeDraw",
    "LifeEpisode",
    "after_branch",
    "condition_names",
    "draw_life",
    "life_condition",
    "episode_branch",
    "life_branch",
    "load_life",
    "parse_life_branch",
    "pretrain_branch",
    "shipped_lives",
]
