"""Model 1 of the paper: a feed-forward network, 3 hidden layers of 256, trained with
binary cross-entropy and a decaying learning rate.

CPU only and deterministic for a seed: weights are initialized and minibatches
drawn from a local ``torch.Generator`` (the global torch RNG is never touched), and
fitting and predicting run on one intra-op thread with deterministic algorithms,
so the floating-point reduction order does not depend on the machine's core count.
Training is bounded (at most :attr:`NeuralNetworkModel.max_steps` minibatch steps,
stopping early when the epoch loss plateaus) so a fit at 10,000 trials stays
within seconds; a refit during exploration fine-tunes the current weights instead
of starting over (:meth:`NeuralNetworkModel.update`).

Both networks follow :mod:`llcps.models.schedule`: past 4,096 trials they are fitted on
the first ``4,096 x 2^k`` trials, and in between a grown training set is learned by a
*warm start*, a short run from the current weights on the new rows beside a replay of
at most :data:`REPLAY_ROWS` rows of the set learned so far (a uniform sample by a hash
of each row's position, kept in the artifact). Unlike naive Bayes's counts this depends
on how the set grew, one batch or many; docs/world_models.md gives the held-out cost.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Any, ClassVar, Iterator, Mapping

import numpy as np
import torch
from torch import nn

from llcps.models.artifact import array
from llcps.models.goal import GoalLearner, Standardizer
from llcps.models.learned import N_FEATURES, N_LABELS, EncodedWorldModel
from llcps.models.families import N_STRATA, stratum_of
from llcps.models.relational import N_GOAL_FEATURES


#: Most rows of the learned set kept for replay.
REPLAY_ROWS = 1024
#: A warm start trains on the new rows and this many times as many replayed rows, for
#: :data:`WARM_EPOCHS` passes over them.
REPLAY_SHARE = 3
WARM_EPOCHS = 2


def warm_rows(replay: Mapping[str, np.ndarray], new: int, generator: torch.Generator) -> np.ndarray:
    """Which replayed rows a warm start on ``new`` rows trains beside: a sample of
    ``REPLAY_SHARE * new`` of them (all, if the replay holds fewer)."""
    held = len(replay["priority"])
    take = min(held, REPLAY_SHARE * new)
    return np.sort(torch.randperm(held, generator=generator)[:take].numpy())


def warm_steps(rows: int, batch: int) -> int:
    """Minibatch steps of a warm start on ``rows`` rows: :data:`WARM_EPOCHS` passes."""
    return WARM_EPOCHS * math.ceil(rows / min(batch, rows))


_MASK64 = (1 << 64) - 1


def replay_priority(seed: int, positions: np.ndarray) -> np.ndarray:
    """A hash (splitmix64) of each row's position in the learned set, salted by ``seed``:
    the replay keeps the rows of smallest priority, a uniform sample of the set."""
    with np.errstate(over="ignore"):
        x = positions.astype(np.uint64) + np.uint64((seed * 0x9E3779B97F4A7C15) & _MASK64)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def grown_replay(
    seed: int, replay: Mapping[str, np.ndarray] | None, first: int, rows: Mapping[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """The :data:`REPLAY_ROWS` rows of smallest priority among ``replay``'s and ``rows``
    (arrays of one length, the rows learned from position ``first`` on), in their order."""
    n = len(next(iter(rows.values())))
    rows = {"priority": replay_priority(seed, np.arange(first, first + n)), **rows}
    merged = {k: v if replay is None else np.concatenate([replay[k], v]) for k, v in rows.items()}
    keep = np.sort(np.argsort(merged["priority"], kind="stable")[:REPLAY_ROWS])
    return {k: v[keep] for k, v in merged.items()}


def replay_arrays(replay: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {f"replay/{k}": v for k, v in replay.items()}


def load_replay(arrays: Mapping[str, np.ndarray], shapes: Mapping[str, tuple[int, ...]], kinds: Mapping[str, str]) -> dict[str, np.ndarray]:
    """A stored replay, checked: at most :data:`REPLAY_ROWS` rows, each array its shape and kind."""
    n = len(array(arrays, "replay/priority", (None,), kind="u"))
    if n > REPLAY_ROWS:
        raise ValueError(f"a replay holds at most {REPLAY_ROWS} rows, not {n}")
    kinds = {"priority": "u", **kinds}
    return {k: array(arrays, f"replay/{k}", (n, *shape), kind=kinds.get(k, "f")) for k, shape in {"priority": (), **shapes}.items()}


@contextmanager
def _deterministic_torch() -> Iterator[None]:
    """One intra-op thread and deterministic kernels, restored afterwards."""
    threads = torch.get_num_threads()
    deterministic = torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(deterministic)
        torch.set_num_threads(threads)


def build_network(
    hidden: tuple[int, ...], generator: torch.Generator | None, *, inputs: int = N_FEATURES, outputs: int = N_LABELS
) -> nn.Sequential:
    """The MLP ``inputs -> hidden... -> outputs`` (logits), ReLU between layers
    (Omega's: 34 -> 3 x 256 -> 6).

    With a generator the layers get PyTorch's default Linear initialization drawn
    from it; without one they are left uninitialized (to be loaded).
    """
    layers: list[nn.Module] = []
    width = inputs
    for size in (*hidden, outputs):
        linear = nn.utils.skip_init(nn.Linear, width, size)
        if generator is not None:
            nn.init.kaiming_uniform_(linear.weight, a=math.sqrt(5), generator=generator)
            bound = 1.0 / math.sqrt(width)
            nn.init.uniform_(linear.bias, -bound, bound, generator=generator)
        layers += [linear, nn.ReLU()]
        width = size
    return nn.Sequential(*layers[:-1])


def network_arrays(network: nn.Module) -> dict[str, np.ndarray]:
    """A network's weights as ``net/<parameter>`` arrays for the store."""
    return {f"net/{key}": value.detach().numpy().copy() for key, value in network.state_dict().items()}


def load_weights(network: nn.Module, arrays: Mapping[str, np.ndarray]) -> nn.Module:
    """``network`` (built to the stored shape) with the weights of :func:`network_arrays`, in eval mode.

    Every array is checked for its name, shape and finiteness (:func:`array`), so a
    damaged row raises a project error instead of loading garbage.
    """
    state = {
        key: torch.from_numpy(array(arrays, f"net/{key}", tuple(value.shape)).astype(np.float32))
        for key, value in network.state_dict().items()
    }
    network.load_state_dict(state, strict=True)
    network.eval()
    return network


class NeuralNetworkModel(EncodedWorldModel):
    """Paper model 1: a multi-label feed-forward network."""

    name: ClassVar[str] = "nn"

    hidden: ClassVar[tuple[int, ...]] = (256, 256, 256)
    batch_size: ClassVar[int] = 128
    #: Upper bounds on minibatch steps (the refit-time budget) and on epochs (against
    #: memorizing a small training set).
    max_steps: ClassVar[int] = 400
    max_epochs: ClassVar[int] = 60
    learning_rate: ClassVar[float] = 2e-3
    #: The learning rate decays exponentially to this fraction over the planned steps.
    final_lr_fraction: ClassVar[float] = 0.05
    weight_decay: ClassVar[float] = 1e-4
    #: Stop after this many epochs without the epoch loss improving by min_improvement.
    patience: ClassVar[int] = 10
    min_improvement: ClassVar[float] = 1e-3
    #: A refit during exploration (:meth:`update`) continues from the current weights for
    #: at most this many steps, starting at this fraction of the learning rate.
    update_steps: ClassVar[int] = 40
    update_lr_fraction: ClassVar[float] = 0.25
    scheduled: ClassVar[bool] = True

    def _reset(self) -> None:
        self._network: nn.Sequential | None = None
        self.training_log: dict[str, Any] = {}
        #: The replay of a warm start: encoded rows, their outcomes and priorities.
        self.replay: dict[str, np.ndarray] = {}

    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        with _deterministic_torch():
            generator = torch.Generator().manual_seed(self.seed & 0xFFFF_FFFF_FFFF_FFFF)
            network = build_network(self.hidden, generator)
            self.training_log = self._train(
                network, features, outcomes, generator, max_steps=self.max_steps, learning_rate=self.learning_rate
            )
        self._network = network
        self.replay = self._grown_replay(None, 0, features, outcomes)

    def _grown_replay(self, replay: dict[str, np.ndarray] | None, first: int, features: np.ndarray, outcomes: np.ndarray) -> dict[str, np.ndarray]:
        return grown_replay(self.seed, replay, first, {"features": features.astype(np.float32), "outcomes": outcomes.astype(np.uint8)})

    def _count(self, raw: np.ndarray, outcomes: np.ndarray) -> None:
        """Count the new trials into the prior, and learn them by a warm start beside the replay."""
        first = self.n_trials
        super()._count(raw, outcomes)
        if self._network is None or not len(raw):
            return
        features = self.encoder.transform(raw)
        with _deterministic_torch():
            generator = torch.Generator().manual_seed((self.seed * 1_000_003 + first) & 0xFFFF_FFFF_FFFF_FFFF)
            old = warm_rows(self.replay, len(raw), generator)
            self.training_log = self._train(
                self._network,
                np.concatenate([features, self.replay["features"][old]]),
                np.concatenate([outcomes, self.replay["outcomes"][old]]),
                generator,
                max_steps=min(self.max_steps, warm_steps(len(raw) + len(old), self.batch_size)),
                learning_rate=self.learning_rate * self.update_lr_fraction,
            )
        self.replay = self._grown_replay(self.replay, first, features, outcomes)

    def _can_continue(self) -> bool:
        return self._network is not None

    def _continue_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        """Fine-tune the current weights on the grown set: a short run at a lower rate.

        A within-episode refit sees the set it was fitted on plus a few trials; starting
        from the weights already fitted, :attr:`update_steps` steps at
        :attr:`update_lr_fraction` of the rate take in the new trials for a fraction of a
        full fit's cost. The minibatch order is drawn from the seed and the set's size.
        """
        assert self._network is not None
        with _deterministic_torch():
            stream = (self.seed * 1_000_003 + len(features)) & 0xFFFF_FFFF_FFFF_FFFF
            generator = torch.Generator().manual_seed(stream)
            self.training_log = self._train(
                self._network,
                features,
                outcomes,
                generator,
                max_steps=self.update_steps,
                learning_rate=self.learning_rate * self.update_lr_fraction,
            )

    def _train(
        self,
        network: nn.Sequential,
        features: np.ndarray,
        outcomes: np.ndarray,
        generator: torch.Generator,
        *,
        max_steps: int,
        learning_rate: float,
    ) -> dict[str, Any]:
        """Adam on binary cross-entropy with an exponentially decaying rate; returns the training log."""
        inputs = torch.from_numpy(np.ascontiguousarray(features, dtype=np.float32))
        targets = torch.from_numpy(outcomes.astype(np.float32))
        optimizer = torch.optim.Adam(network.parameters(), lr=learning_rate, weight_decay=self.weight_decay)
        n, batch = len(inputs), min(self.batch_size, len(inputs))
        planned = min(max_steps, self.max_epochs * math.ceil(n / batch))
        gamma = self.final_lr_fraction ** (1.0 / planned)
        schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=gamma)
        loss_fn = nn.BCEWithLogitsLoss()
        steps = epochs = stale = 0
        best = math.inf
        epoch_loss = math.nan
        network.train()
        while steps < planned and stale < self.patience:
            order = torch.randperm(n, generator=generator)
            total, seen = 0.0, 0
            for start in range(0, n, batch):
                if steps == planned:
                    break
                index = order[start : start + batch]
                optimizer.zero_grad(set_to_none=True)
                loss = loss_fn(network(inputs[index]), targets[index])
                loss.backward()
                optimizer.step()
                schedule.step()
                steps += 1
                total += loss.item() * len(index)
                seen += len(index)
            epochs += 1
            epoch_loss = total / max(seen, 1)
            if epoch_loss < best - self.min_improvement:
                best, stale = epoch_loss, 0
            else:
                stale += 1
        network.eval()
        return {"steps": steps, "epochs": epochs, "final_loss": epoch_loss}

    def _predict_encoded(self, features: np.ndarray) -> np.ndarray:
        assert self._network is not None
        with _deterministic_torch(), torch.inference_mode():
            logits = self._network(torch.from_numpy(np.ascontiguousarray(features, dtype=np.float32)))
            return torch.sigmoid(logits).double().numpy()

    def _goal_learner(self) -> GoalLearner:
        return NeuralGoal(self.seed)

    def _export_learner(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        assert self._network is not None
        arrays = {**network_arrays(self._network), **replay_arrays(self.replay)}
        meta = {
            "hidden": list(self.hidden),
            "training": self.training_log,
            "max_steps": self.max_steps,
            "batch_size": self.batch_size,
        }
        return arrays, meta

    def _import_learner(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> None:
        self._network = load_weights(build_network(self.hidden, None), arrays)
        self.training_log = dict(meta.get("training", {}))
        self.replay = load_replay(arrays, {"features": (N_FEATURES,), "outcomes": (N_LABELS,)}, {"outcomes": "u"})
        if np.any(self.replay["outcomes"] > 1):
            raise ValueError("replayed outcomes must be 0/1")


class NeuralGoal(GoalLearner):
    """A feed-forward network on standardized (candidate, atom) rows, weighted binary cross-entropy.

    Smaller than Omega's (two hidden layers of 64), with one output per (predicate, sign)
    stratum: the hidden layers are shared by every kind of change, and a row's loss and
    prediction use its own stratum's output (what makes things touch need not put them in
    containers). Deterministic for a seed like the Omega network (local generator, one
    thread, deterministic kernels); at most :attr:`max_steps` minibatch steps with the
    learning rate decaying to 5 %.
    """

    name: ClassVar[str] = "nn"
    hidden: ClassVar[tuple[int, ...]] = (64, 64)
    batch_size: ClassVar[int] = 256
    max_steps: ClassVar[int] = 1000
    max_epochs: ClassVar[int] = 40
    learning_rate: ClassVar[float] = 3e-3
    final_lr_fraction: ClassVar[float] = 0.05
    weight_decay: ClassVar[float] = 1e-4
    #: A warm start (:meth:`extend`) runs at this fraction of the rate.
    update_lr_fraction: ClassVar[float] = 0.25
    scheduled: ClassVar[bool] = True

    def __init__(self, seed: int) -> None:
        super().__init__(seed)
        self.scaler = Standardizer()
        self._network: nn.Sequential | None = None
        #: Rows learned, and the replay of a warm start.
        self.rows = 0
        self.replay: dict[str, np.ndarray] = {}

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        self.scaler.fit(features, weights)
        with _deterministic_torch():
            generator = torch.Generator().manual_seed((self.seed ^ 0x60A1) & 0xFFFF_FFFF_FFFF_FFFF)
            network = build_network(self.hidden, generator, inputs=N_GOAL_FEATURES, outputs=N_STRATA)
            self._train(network, features, labels, weights, generator, max_steps=self.max_steps, learning_rate=self.learning_rate)
        self._network = network
        self.rows = len(labels)
        self.replay = self._grown_replay(None, 0, features, labels, weights)

    def extend(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        """A warm start: a short run from the current weights on the new rows beside the replay."""
        if self._network is None or not len(labels):
            return
        with _deterministic_torch():
            generator = torch.Generator().manual_seed((self.seed * 1_000_003 + self.rows) & 0xFFFF_FFFF_FFFF_FFFF)
            old = warm_rows(self.replay, len(labels), generator)
            self._train(
                self._network,
                np.concatenate([features, self.replay["features"][old]]),
                np.concatenate([labels, self.replay["labels"][old]]),
                np.concatenate([weights, self.replay["weights"][old]]),
                generator,
                max_steps=min(self.max_steps, warm_steps(len(labels) + len(old), self.batch_size)),
                learning_rate=self.learning_rate * self.update_lr_fraction,
            )
        self.replay = self._grown_replay(self.replay, self.rows, features, labels, weights)
        self.rows += len(labels)

    def _grown_replay(
        self, replay: dict[str, np.ndarray] | None, first: int, features: np.ndarray, labels: np.ndarray, weights: np.ndarray
    ) -> dict[str, np.ndarray]:
        columns = {"features": features.astype(np.float64), "labels": labels.astype(np.uint8), "weights": weights.astype(np.float64)}
        return grown_replay(self.seed, replay, first, columns)

    def _train(
        self,
        network: nn.Sequential,
        features: np.ndarray,
        labels: np.ndarray,
        weights: np.ndarray,
        generator: torch.Generator,
        *,
        max_steps: int,
        learning_rate: float,
    ) -> None:
        """Adam on the weighted binary cross-entropy of each row's own stratum output."""
        inputs = torch.from_numpy(self.scaler.transform(features))
        strata = torch.from_numpy(stratum_of(features))
        targets = torch.from_numpy(labels.astype(np.float32))
        w = torch.from_numpy((weights / weights.mean()).astype(np.float32))
        optimizer = torch.optim.Adam(network.parameters(), lr=learning_rate, weight_decay=self.weight_decay)
        n, batch = len(inputs), min(self.batch_size, len(inputs))
        planned = min(max_steps, self.max_epochs * math.ceil(n / batch))
        schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=self.final_lr_fraction ** (1.0 / planned))
        loss_fn = nn.BCEWithLogitsLoss(reduction="none")
        steps = 0
        network.train()
        while steps < planned:
            order = torch.randperm(n, generator=generator)
            for start in range(0, n, batch):
                if steps == planned:
                    break
                index = order[start : start + batch]
                optimizer.zero_grad(set_to_none=True)
                logits = network(inputs[index]).gather(1, strata[index, None])[:, 0]
                loss = (loss_fn(logits, targets[index]) * w[index]).mean()
                loss.backward()
                optimizer.step()
                schedule.step()
                steps += 1
        network.eval()

    def predict(self, features: np.ndarray) -> np.ndarray:
        assert self._network is not None
        with _deterministic_torch(), torch.inference_mode():
            strata = torch.from_numpy(stratum_of(features))
            logits = self._network(torch.from_numpy(self.scaler.transform(features))).gather(1, strata[:, None])[:, 0]
            return torch.sigmoid(logits).double().numpy()

    def export(self) -> dict[str, np.ndarray]:
        assert self._network is not None
        return {**network_arrays(self._network), **self.scaler.export("scaler"), **replay_arrays(self.replay), "rows": np.array([self.rows])}

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        self.scaler.load(arrays, "scaler")
        self._network = load_weights(build_network(self.hidden, None, inputs=N_GOAL_FEATURES, outputs=N_STRATA), arrays)
        self.rows = int(array(arrays, "rows", (1,), kind="iu")[0])
        self.replay = load_replay(
            arrays, {"features": (N_GOAL_FEATURES,), "labels": (), "weights": ()}, {"labels": "u"}
        )
        if np.any(self.replay["labels"] > 1) or np.any(self.replay["weights"] <= 0) or len(self.replay["labels"]) > self.rows:
            raise ValueError("replayed rows must have 0/1 labels and positive weights, no more than the rows learned")
