"""The CPS scenarios: the paper's three (Figure 1) and more, each declared in a TOML
file shipped in ``llcps/scenarios/shipped/``. ``SCENARIOS`` is the one list the CLI,
the experiments and the tests read; :func:`get_scenario` also reads a scenario
straight from a file. See docs/scenarios.md for the file format and pictures.

Light to import: the shipped files are read and checked (pydantic, the knowledge
base's PDDL) when ``SCENARIOS`` or ``RESERVED`` is first used, not at import, so
commands that never touch a scenario do not pay for it.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from llcps.scenarios.base import CONDITIONS, Scenario, lookup

if TYPE_CHECKING:
    from llcps.scenarios.loader import ScenarioSource

#: Where the shipped scenario files are (package data).
SHIPPED_DIR = Path(__file__).parent / "shipped"

# Bound on first use by __getattr__ (_registry): declared here, without a value.
#: name -> scenario, every shipped file (read when first used).
SCENARIOS: dict[str, Scenario]
#: Names and aliases of the shipped scenarios: a file of one's own may not take them.
RESERVED: dict[str, str]

_LOCK = threading.Lock()
_FILES: dict[tuple[str, int, int], Scenario] = {}


def _shipped_files() -> list[Path]:
    return sorted(SHIPPED_DIR.glob("*.toml"))


def _shipped() -> dict[str, Scenario]:
    from llcps.scenarios.loader import read_file

    found: dict[str, Scenario] = {}
    for path in _shipped_files():
        scenario = Scenario.from_source(read_file(path))
        found[scenario.name] = scenario
    return found


def _registry() -> tuple[dict[str, Scenario], dict[str, str]]:
    """``SCENARIOS`` and ``RESERVED``, the shipped files read and checked the first time."""
    names = globals()
    with _LOCK:
        if "SCENARIOS" not in names:
            scenarios = _shipped()
            names["RESERVED"] = {
                **{s.name: s.name for s in scenarios.values()},
                **{s.alias: s.name for s in scenarios.values() if s.alias},
            }
            names["SCENARIOS"] = scenarios
    return names["SCENARIOS"], names["RESERVED"]


def __getattr__(name: str) -> Any:
    if name in ("SCENARIOS", "RESERVED"):
        _registry()
        return globals()[name]
    if name == "ScenarioSource":
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


def get_scenario(name: str) -> Scenario:
    """A scenario by name or alias (``scenario2`` or ``container``), or from a ``.toml`` file."""
    scenarios, reserved = _registry()
    if not is_path(name):
        return lookup(scenarios, name)
    from llcps.scenarios.loader import read_file

    path = Path(name)
    for scenario in scenarios.values():
        if scenario.source is not None and scenario.source.path is not None and path.exists():
            if path.resolve() == scenario.source.path.resolve():
                return scenario
    try:
        stat = path.stat()
        key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    except OSError:
        key = None
    if key is not None and key in _FILES:
        return _FILES[key]
    scenario = Scenario.from_source(read_file(path, reserved=reserved))
    if key is not None:
        _FILES[key] = scenario
    return scenario


__all__ = ["CONDITIONS", "RESERVED", "SCENARIOS", "SHIPPED_DIR", "Scenario", "ScenarioSource", "get_scenario", "is_path", "shipped_names"]
