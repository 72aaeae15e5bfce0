"""WORLD_MODELS: the one list of world models (CLI choices, docs, test parameters),
with the default a command uses when given none.

Entries import their module on first use, so ``import llcps.models`` (and every CLI
command that only needs the names) does not pay for importing scikit-learn or torch.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

from llcps.registry import Registry

if TYPE_CHECKING:
    from llcps.models.base import WorldModel


@dataclass(frozen=True)
class WorldModelEntry:
    """A registered world model; calling it with a seed makes an unfitted model."""

    name: str
    module: str
    class_name: str
    description: str
    #: The model's number in the paper (1: the network, 2: naive Bayes); 0 for baselines.
    paper: int = 0

    def model_class(self) -> type[WorldModel]:
        return getattr(importlib.import_module(self.module), self.class_name)

    def __call__(self, seed: int) -> WorldModel:
        return self.model_class()(seed)

    def load(self, artifact: bytes, meta: Mapping[str, Any], seed: int) -> WorldModel:
        """Load a stored artifact of this model (see :meth:`WorldModel.from_artifact`)."""
        return self.model_class().from_artifact(artifact, meta, seed)


def _entries(*entries: WorldModelEntry) -> dict[str, WorldModelEntry]:
    return {entry.name: entry for entry in entries}


#: name -> factory(seed) of every world model; its default is naive Bayes, the paper's model 2.
WORLD_MODELS: Registry[WorldModelEntry] = Registry(
    "world model",
    _entries(
        WorldModelEntry(
            "nb",
            "llcps.models.naive_bayes",
            "NaiveBayesModel",
            "Bernoulli naive Bayes, one classifier per Omega bit (paper model 2)",
            paper=2,
        ),
        WorldModelEntry(
            "nn",
            "llcps.models.neural",
            "NeuralNetworkModel",
            "feed-forward network, 3 x 256 hidden, BCE loss, decaying learning rate (paper model 1)",
            paper=1,
        ),
        WorldModelEntry("random", "llcps.models.baselines", "RandomModel", "no model: a seeded random exploration order"),
        WorldModelEntry("logreg", "llcps.models.baselines", "LogisticRegressionModel", "logistic regression per Omega bit (linear)"),
        WorldModelEntry("forest", "llcps.models.baselines", "RandomForestModel", "random forest over all Omega bits (non-linear)"),
    ),
    default="nb",
)

#: The paper's models, the default of commands that fit "the models".
PAPER_MODELS: tuple[str, ...] = tuple(e.name for e in sorted((e for e in WORLD_MODELS.values() if e.paper), key=lambda e: e.paper))


def world_model_entry(name: str) -> WorldModelEntry:
    """The registry entry of ``name``.

    Raises:
        UnknownNameError: listing the known names.
    """
    return WORLD_MODELS.get_entry(name)


def make_world_model(name: str, seed: int) -> WorldModel:
    """An unfitted world model by registry name."""
    return world_model_entry(name)(seed)


def load_world_model(artifact: bytes, meta: Mapping[str, Any], *, seed: int) -> WorldModel:
    """Load a stored artifact, dispatching on ``meta["model"]``.

    Raises:
        LlcpsError: unknown model name, or a rejected artifact.
    """
    name = meta.get("model") if isinstance(meta, Mapping) else None
    return world_model_entry(str(name)).load(artifact, meta, seed)
