"""Shared fixtures. Keep this small: one fixture per idea."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Iterator

import pytest

FIXTURES = Path(__file__).parent / "fixtures"
sys.path.insert(0, str(FIXTURES))

from store_writer import sample_trial  # noqa: E402

from llcps.store import Store  # noqa: E402


@pytest.fixture
def store(tmp_path: Path) -> Iterator[Store]:
    """A fresh SQLite experience store with a `main` branch."""
    with Store.open(str(tmp_path / "llcps.db"), create=True) as opened:
        yield opened


@pytest.fixture
def new_trial():  # noqa: ANN201 - returns the sample_trial factory
    """``new_trial(seed, branch=..., source=..., **overrides) -> TrialRecord``."""
    return sample_trial
