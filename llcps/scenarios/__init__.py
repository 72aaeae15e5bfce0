"""The CPS scenarios: the paper's three (Figure 1) and more, each declared in a TOML
file shipped in ``llcps/scenarios/shipped/``. ``SCENARIOS`` is the one list the CLI,
the experiments and the tests read; :func:`get_scenario` also reads a scenario
straight from a file. See docs/scenarios.md for the file format and pictures.
"""

from __future__ import annotations

import os
from pathlib import Path

from llcps.scenarios.base import CONDITIONS, Scenario, lookup
from llcps.scenarios.loader import ScenarioSource, read_file

#: Where the shipped scenario files are (package data).
SHIPPED_DIR = Path(__file__).parent / "shipped"


def _shipped() -> dict[str, Scenario]:
    found: dict[str, Scenario] = {}
    for path in sorted(SHIPPED_DIR.glob("*.toml")):
        scenario = Scenario.from_source(read_file(path))
        found[scenario.name] = scenario
    return found


SCENARIOS: dict[str, Scenario] = _shipped()

#: Names and aliases of the shipped scenarios: a file of one's own may not take them.
RESERVED: dict[str, str] = {
    **{s.name: s.name for s in SCENARIOS.values()},
    **{s.alias: s.name for s in SCENARIOS.values() if s.alias},
}

_FILES: dict[tuple[str, int, int], Scenario] = {}


def is_path(name: str) -> bool:
    """Whether a scenario argument names a file rather than a registered scenario."""
    return name.endswith(".toml") or os.sep in name or "/" in name


def get_scenario(name: str) -> Scenario:
    """A scenario by name or alias (``scenario2`` or ``container``), or from a ``.toml`` file."""
    if not is_path(name):
        return lookup(SCENARIOS, name)
    path = Path(name)
    for scenario in SCENARIOS.values():
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
    scenario = Scenario.from_source(read_file(path, reserved=RESERVED))
    if key is not None:
        _FILES[key] = scenario
    return scenario


__all__ = ["CONDITIONS", "RESERVED", "SCENARIOS", "SHIPPED_DIR", "Scenario", "ScenarioSource", "get_scenario", "is_path"]
