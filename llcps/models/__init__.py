"""World models W : (a, r, nabla, X) -> Omega and the measures that rank exploration.

- W predicts, for an action a with its controller settings r, its arguments nabla and
  their features X (Table 1), the probability of each bit of the meta-outcome Omega
  (Table 2): :class:`~llcps.models.base.WorldModel`, the paper's network and naive
  Bayes and the baselines, named in ``WORLD_MODELS`` (:mod:`~llcps.models.registry`).
  A goal-aware head learns which atoms a candidate makes hold (:mod:`~llcps.models.goal`).
- The measures turn predictions into an exploration order: ``MEASURES``
  (:mod:`~llcps.models.measures`).
- Fitted models are stored on their branch and reused (:mod:`~llcps.models.persistence`)
  as safe artifacts (:mod:`~llcps.models.artifact`).

Light to import: the registries name every model and measure without importing numpy,
scikit-learn or torch (a model's module loads when the model is first made;
``WorldModel`` and ``fit_or_load`` when first used).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from llcps.models.measures import MEASURES, PAPER_MEASURES, rank
from llcps.models.registry import PAPER_MODELS, WORLD_MODELS, load_world_model, make_world_model

if TYPE_CHECKING:
    from llcps.models.base import WorldModel
    from llcps.models.persistence import fit_or_load


def __getattr__(name: str) -> Any:
    if name == "WorldModel":
        from llcps.models.base import WorldModel

        return WorldModel
    if name == "fit_or_load":
        from llcps.models.persistence import fit_or_load

        return fit_or_load
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")



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
