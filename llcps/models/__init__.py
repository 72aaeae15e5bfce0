"""World models W : (a, r, nabla, X) -> Omega and the measures that rank exploration.

Light to import: the registries name every model and measure without importing
scikit-learn or torch (a model's module loads when the model is first made).
"""

from __future__ import annotations

from llcps.models.base import WorldModel
from llcps.models.measures import MEASURES, PAPER_MEASURES, rank
from llcps.models.persistence import fit_or_load
from llcps.models.registry import PAPER_MODELS, WORLD_MODELS, load_world_model, make_world_model

__all__ = [
    "MEASURES",
    "PAPER_MEASURES",
    "PAPER_MODELS",
    "WORLD_MODELS",
    "WorldModel",
    "fit_or_load",
    "load_world_model",
    "make_world_model",
    "rank",
]
