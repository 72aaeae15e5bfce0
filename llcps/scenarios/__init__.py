"""The CPS scenarios as data: the paper's three (Figure 1) and more, each declared in a
TOML file shipped in ``llcps/scenarios/shipped/``.

A scenario holds one scene in two conditions, the *original* one, where the nominal
plan from K succeeds, and the *novelty* one, where the world has changed so that it
fails and the robot must solve the problem creatively; and the goal sg as PDDL atoms.
The file format (:mod:`~llcps.scenarios.file_format`), its reading and checks
(:mod:`~llcps.scenarios.loader`, :mod:`~llcps.scenarios.layout`) and the variants drawn
from its ranges (:mod:`~llcps.scenarios.variants`) make every scenario plain data.
 ``SCENARIOS`` is the one list the CLI,
the experiments and the tests read; :func:`get_scenario` also reads a scenario
straight from a file. See docs/scenarios.md for the file format and pictures.

Light to import: ``SCENARIOS`` is a :class:`~llcps.registry.Registry` whose shipped
files are read and checked (pydantic, the knowledge base's PDDL) when it is first
used, not at import, so commands that never touch a scenario do not pay for it.
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Mapping

from llcps.registry import Registry
from llcps.scenarios.base import CONDITIONS, Scenario, lookup

if TYPE_CHECKING:
    from llcps.scenarios.loader import ScenarioSource

#: Where the shipped scenario files are (package data).
SHIPPED_DIR = Path(__file__).parent / "shipped"

#: Scenario files read from a path this process remembers (the same file unchanged is read once).
FILE_MEMO_SIZE = 128


def _shipped_files() -> list[Path]:
    """The shipped files in number order (scenario2 before scenario10)."""
    return sorted(SHIPPED_DIR.glob("*.toml"), key=_number_order)


def _number_order(path: Path) -> tuple[str, int, str]:
    match = re.fullmatch(r"(.*?)(\d+)", path.stem)
    return (match[1], int(match[2]), "") if match else (path.stem, -1, path.stem)


def _read(path: Path, reserved: Mapping[str, str] | None = None) -> Scenario:
    """The scenario of a file, read and checked."""
    # The loader validates with pydantic: it loads when a scenario is first read.
    from llcps.scenarios.loader import read_file

    return Scenario.from_source(read_file(path, reserved=reserved))


def _shipped() -> tuple[dict[str, Scenario], dict[str, str]]:
    """Every shipped file read and checked, and the aliases the files declare."""
    found: dict[str, Scenario] = {}
    for path in _shipped_files():
        scenario = _read(path)
        found[scenario.name] = scenario
    return found, {s.alias: s.name for s in found.values() if s.alias}


#: name -> scenario, every shipped file (read and checked when first used), with the
#: files' aliases (``container`` for ``scenario2``).
SCENARIOS: Registry[Scenario] = Registry("scenario", loader=_shipped, hint_extra=("or a path to a .toml file",))


class _Reserved(Mapping[str, str]):
    """Names and aliases of the shipped scenarios, each to its scenario's name: a file
    of one's own may not take them (read from ``SCENARIOS`` when first used)."""

    def _names(self) -> dict[str, str]:
        return {**{name: name for name in SCENARIOS}, **SCENARIOS.aliases}

    def __getitem__(self, name: str) -> str:
        return self._names()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())


#: Names and aliases of the shipped scenarios: a file of one's own may not take them.
RESERVED: Mapping[str, str] = _Reserved()


def __getattr__(name: str) -> Any:
    if name == "ScenarioSource":  # the loader validates with pydantic: loaded when asked for
        from llcps.scenarios.loader import ScenarioSource

        return ScenarioSource
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def shipped_names() -> dict[str, str]:
    """name -> alias ("" for none) of every shipped scenario, in ``SCENARIOS``' order,
    from the files' own ``name`` and ``alias`` keys without checking the files: cheap
    enough for help texts built when the CLI starts (tests check it against ``SCENARIOS``)."""
    import tomllib

    names: dict[str, str] = {}
    for path in _shipped_files():
        with path.open("rb") as file:
            data = tomllib.load(file)
        names[str(data["name"])] = str(data.get("alias") or "")
    return names


def is_path(name: str) -> bool:
    """Whether a scenario argument names a file rather than a registered scenario."""
    return name.endswith(".toml") or os.sep in name or "/" in name


@functools.lru_cache(maxsize=FILE_MEMO_SIZE)
def _read_file(name: str, resolved: str, mtime_ns: int, size: int) -> Scenario:
    """The scenario of the file ``name`` as it is now (its resolved path, time and size are the key)."""
    return _read(Path(name), RESERVED)


def get_scenario(name: str) -> Scenario:
    """A scenario by name or alias (``scenario2`` or ``container``), or from a ``.toml`` file."""
    if not is_path(name):
        return SCENARIOS.get_entry(name)
    path = Path(name)
    for scenario in SCENARIOS.values():
        if scenario.source is not None and scenario.source.path is not None and path.exists():
            if path.resolve() == scenario.source.path.resolve():
                return scenario
    try:
        stat = path.stat()
        resolved = str(path.resolve())
    except OSError:
        return _read(path, RESERVED)
    return _read_file(name, resolved, stat.st_mtime_ns, stat.st_size)


def clear_caches() -> None:
    """Forget the scenario files read from paths (the shipped scenarios stay: they are package data)."""
    _read_file.cache_clear()


__all__ = [
    "CONDITIONS",
    "RESERVED",
    "SCENARIOS",
    "SHIPPED_DIR",
    "Scenario",
    "ScenarioSource",
    "clear_caches",
    "get_scenario",
    "is_path",
    "lookup",
    "shipped_names",
]
