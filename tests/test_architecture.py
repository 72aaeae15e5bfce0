"""The layering is a contract: `lint-imports` (pyproject.toml) keeps imports downward and
free of circles, and it fails when an import goes the wrong way."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")

pytestmark = pytest.mark.skipif(not LINT_IMPORTS.exists(), reason="import-linter is not installed: pip install -e '.[dev]'")


def _lint(tree: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache"], cwd=tree, env=env, capture_output=True, text=True, timeout=300
    )


def _copy(tmp_path: Path) -> Path:
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "llcps", tree / "llcps", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree / "pyproject.toml")
    return tree


def test_the_tree_keeps_its_import_contracts() -> None:
    result = _lint(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


@pytest.mark.parametrize(
    ("module", "statement", "says"),
    [
        # a copy of the tree as it is: the contract holds (the check below is not an artefact of copying)
        ("llcps/errors.py", "", None),
        # a lower layer reaching up: the store importing the agent's package
        ("llcps/store/__init__.py", "\nimport llcps.cps  # noqa: E402,F401\n", "is not allowed to import llcps.cps"),
        # two modules of one package importing each other (registry already imports errors)
        ("llcps/errors.py", "\nfrom llcps import registry  # noqa: E402,F401\n", "llcps.errors"),
    ],
    ids=["unchanged", "upward", "circle"],
)
def test_a_wrong_way_import_breaks_the_contract(tmp_path: Path, module: str, statement: str, says: str | None) -> None:
    tree = _copy(tmp_path)
    path = tree / module
    path.write_text(path.read_text() + statement)
    result = _lint(tree)
    if says is None:
        assert result.returncode == 0, result.stdout + result.stderr
    else:
        assert result.returncode != 0, result.stdout
        assert "BROKEN" in result.stdout and says in result.stdout, result.stdout
