"""Branch visibility against a reference model, over random trees of forks and writes.

The model restates the rule directly: visible(B) = own(B) ∪ {t ∈ visible(parent) : t.id <= fork(B)},
and the same with watermarks for operators.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule, run_state_machine_as_test

from llcps.errors import StoreError
from llcps.store import Store


@dataclass
class Model:
    parent: dict[str, str | None] = field(default_factory=lambda: {"main": None})
    fork: dict[str, int] = field(default_factory=lambda: {"main": 0})
    trials: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> (branch, source)
    operators: dict[int, tuple[str, int]] = field(default_factory=dict)  # id -> (branch, watermark)
    current: str = "main"

    def visible(self, branch: str, items: dict[int, tuple]) -> set[int]:  # type: ignore[type-arg]
        key = 0 if items is self.trials else 1
        own = {i for i, v in items.items() if v[0] == branch}
        parent = self.parent[branch]
        if parent is None:
            return own
        position = (lambda i: i) if key == 0 else (lambda i: items[i][1])
        return own | {i for i in self.visible(parent, items) if position(i) <= self.fork[branch]}

    def max_visible(self, branch: str, source: str | None = None) -> int:
        ids = [i for i in self.visible(branch, self.trials) if source is None or self.trials[i][1] == source]
        return max(ids, default=0)

    def pretrain_point(self, branch: str) -> int:
        """The last pretraining trial before the first trial of another source that follows
        the first pretraining trial (0: none visible)."""
        seen = sorted(self.visible(branch, self.trials))
        point = 0
        for i in seen:
            if self.trials[i][1] == "pretrain":
                point = i
            elif point:
                break
        return point

    def children(self, branch: str) -> list[str]:
        return [b for b, p in self.parent.items() if p == branch]


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("template") / "template.db"
    Store.open(str(path), create=True).close()
    return path


class BranchMachine(RuleBasedStateMachine):
    template: Path

    def __init__(self) -> None:
        super().__init__()
        self.store = self.make_store()
        self.model = Model()
        self.counter = 0
        self.names = 0

    def make_store(self) -> Store:
        """A fresh store (a copy of a template file; other backends override this)."""
        self.dir = Path(tempfile.mkdtemp())
        shutil.copy(self.template, self.dir / "s.db")
        return Store.open(str(self.dir / "s.db"))

    def teardown(self) -> None:
        self.store.close()
        shutil.rmtree(self.dir, ignore_errors=True)

    def _branch(self, data: st.DataObject) -> str:
        return data.draw(st.sampled_from(sorted(self.model.parent)))

    @initialize(n=st.integers(0, 4))
    def pretrain(self, n: int) -> None:
        self._add("main", "pretrain", n)

    def _add(self, branch: str, source: str, n: int) -> None:
        from store_writer import sample_trial

        ids = self.store.add_trials([sample_trial(self.counter + k, branch=branch, source=source) for k in range(n)])
        self.counter += n
        for trial_id in ids:
            self.model.trials[trial_id] = (branch, source)

    @rule(data=st.data(), source=st.sampled_from(["pretrain", "exploration", "plan"]), n=st.integers(1, 3))
    def add_trials(self, data: st.DataObject, source: str, n: int) -> None:
        self._add(self._branch(data), source, n)

    @rule(data=st.data(), how=st.sampled_from(["latest", "pretrain", "id", "zero"]))
    def create_branch(self, data: st.DataObject, how: str) -> None:
        parent = self._branch(data)
        visible = sorted(self.model.visible(parent, self.model.trials))
        if how == "id" and visible:
            at: int | str | None = data.draw(st.sampled_from(visible))
            expected = at
        elif how == "pretrain":
            at, expected = "pretrain", self.model.pretrain_point(parent)
        elif how == "zero":
            at, expected = 0, 0
        else:
            at, expected = None, self.model.max_visible(parent)
        self.names += 1
        name = f"b{self.names}"
        info = self.store.create_branch(name, from_branch=parent, at=at)
        assert (info.parent, info.fork_point) == (parent, expected)
        self.model.parent[name], self.model.fork[name] = parent, int(expected)  # type: ignore[arg-type]

    @rule(data=st.data())
    def add_operator(self, data: st.DataObject) -> None:
        branch = self._branch(data)
        op_id = self.store.add_operator(branch=branch, name="op", pddl="", definition={}, scenario=None, episode_id=None)
        self.model.operators[op_id] = (branch, self.model.max_visible(branch))

    @rule(data=st.data())
    def checkout(self, data: st.DataObject) -> None:
        branch = self._branch(data)
        self.store.checkout(branch)
        self.model.current = branch

    @rule(data=st.data(), to=st.sampled_from(["pretrain", "empty"]))
    def reset(self, data: st.DataObject, to: str) -> None:
        branch = self._branch(data)
        keep = self.model.pretrain_point(branch) if to == "pretrain" else 0
        trials = [i for i, (b, _) in self.model.trials.items() if b == branch and i > keep]
        ops = [i for i, (b, w) in self.model.operators.items() if b == branch and (to == "empty" or w > keep)]
        first = min([*trials, *(self.model.operators[i][1] for i in ops)], default=None)
        blocked = first is not None and any(self.model.fork[c] >= first for c in self.model.children(branch))
        if blocked:
            with pytest.raises(StoreError):
                self.store.reset_branch(branch, to=to, dry_run=False)
            return
        change = self.store.reset_branch(branch, to=to, dry_run=False)
        assert (change.trials, change.operators) == (len(trials), len(ops))
        for i in trials:
            del self.model.trials[i]
        for i in ops:
            del self.model.operators[i]

    @rule(data=st.data())
    def delete(self, data: st.DataObject) -> None:
        branch = self._branch(data)
        if branch == "main" or branch == self.model.current or self.model.children(branch):
            with pytest.raises(StoreError):
                self.store.delete_branch(branch, dry_run=False)
            return
        self.store.delete_branch(branch, dry_run=False)
        del self.model.parent[branch], self.model.fork[branch]
        self.model.trials = {i: v for i, v in self.model.trials.items() if v[0] != branch}
        self.model.operators = {i: v for i, v in self.model.operators.items() if v[0] != branch}

    @invariant()
    def visibility_matches_the_model(self) -> None:
        infos = {b.name: b for b in self.store.list_branches()}
        assert set(infos) == set(self.model.parent)
        assert self.store.current_branch() == self.model.current
        for branch in self.model.parent:
            expected = sorted(self.model.visible(branch, self.model.trials))
            records = self.store.visible_trials(branch)
            assert [t.id for t in records] == expected
            assert [t.id for t in self.store.visible_trials(branch, newest_first=True)] == expected[::-1]
            assert [t.id for t in self.store.visible_trials(branch, source="exploration")] == [i for i in expected if self.model.trials[i][1] == "exploration"]
            assert all(t.branch == self.model.trials[t.id][0] for t in records)
            assert self.store.count_visible_trials(branch) == len(expected)
            assert self.store.max_visible_trial_id(branch) == max(expected, default=0)
            own = sum(1 for b, _ in self.model.trials.values() if b == branch)
            assert (infos[branch].own_trials, infos[branch].visible_trials) == (own, len(expected))
            assert infos[branch].parent == self.model.parent[branch]
            assert [o.id for o in self.store.visible_operators(branch)] == sorted(self.model.visible(branch, self.model.operators))


def run_machine(machine: type[BranchMachine], max_examples: int = 25) -> None:
    run_state_machine_as_test(
        machine,
        settings=settings(
            max_examples=max_examples,
            stateful_step_count=20,
            deadline=None,
            suppress_health_check=[HealthCheck.too_slow],
            phases=[Phase.explicit, Phase.reuse, Phase.generate],  # shrinking store runs takes minutes
        ),
    )


def test_branch_visibility_matches_reference_model(template: Path) -> None:
    BranchMachine.template = template
    run_machine(BranchMachine)
