"""docs/world_models.md describes every registered world model and measure."""

from __future__ import annotations

from pathlib import Path

import pytest

from llcps.models import MEASURES, WORLD_MODELS

GUIDE = (Path(__file__).parents[1] / "docs" / "world_models.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("name", [*WORLD_MODELS, *MEASURES])
def test_guide_names_every_model_and_measure(name):
    assert f"| `{name}` |" in GUIDE
