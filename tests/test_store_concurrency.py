"""Writers queue, and branch visibility holds while several processes write and fork at once.

Branch visibility needs trial ids that commit in increasing order (see
llcps/store/visibility.py). On PostgreSQL a sequence value can commit after a larger
one unless writers are serialized; these tests run on both backends.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

from sqlalchemy import insert

from llcps.store import Store
from llcps.store import backends
from llcps.store import visibility
from llcps.store.tables import Trial
from llcps.store.trials import trial_row

WRITER = Path(__file__).parent / "fixtures" / "branch_writer.py"
WRITERS = 4
STEPS = 30


def test_a_writer_waits_for_the_open_write_transaction(store: Store, new_trial) -> None:  # noqa: ANN001
    """A trial drawn inside an open write transaction commits before any later writer's."""
    first = store.add_trial(new_trial(0))
    done: dict[str, int] = {}
    with store.engine.connect() as conn:
        conn.execution_options(**{backends.WRITE_OPTION: True})
        with conn.begin():
            row = trial_row(new_trial(1), branch_id=1, created_at=store.get_trial(first).created_at and _now())
            held = conn.execute(insert(Trial).values(**row)).inserted_primary_key[0]
            writer = threading.Thread(target=lambda: done.update(id=store.add_trial(new_trial(2))))
            forker = threading.Thread(target=lambda: done.update(fork=store.create_branch("late").fork_point))
            writer.start()
            time.sleep(0.5)
            forker.start()
            time.sleep(0.5)
            assert writer.is_alive() and forker.is_alive(), "a writer did not wait for the open write transaction"
        # committed: the others go on
    writer.join(30)
    forker.join(30)
    assert done["id"] > held > first
    assert done["fork"] >= held  # the fork saw the held trial: it was committed first
    inherited = [t.id for t in store.visible_trials("late") if t.branch == "main"]
    assert held in inherited and inherited == [t.id for t in store.visible_trials("main") if t.id <= done["fork"]]


def _now():  # noqa: ANN202
    from datetime import datetime, timezone

    return datetime.now(timezone.utc).replace(tzinfo=None)


def test_concurrent_writers_and_forks_keep_visibility(store_url: str) -> None:
    """>= 4 processes add trials and fork branches at random, all at once.

    Checked afterwards against the visibility rule: what a branch saw when it was
    forked is what it inherits at the end, a branch's trials up to any watermark one
    of the writers read stay the trials it counted, and every branch's visible set is
    the one :mod:`llcps.store.visibility` computes from the final rows.
    """
    Store.open(store_url, create=True).close()
    procs = [
        subprocess.Popen(
            [sys.executable, str(WRITER), store_url, f"w{i}", str(STEPS), str(i + 1)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        for i in range(WRITERS)
    ]  # fmt: skip
    for proc in procs:  # every writer has the store open: release them together
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready", proc.stderr.read() if proc.stderr else ""
    for proc in procs:
        assert proc.stdin is not None
        proc.stdin.write("go\n")
        proc.stdin.flush()
    outputs = [proc.communicate(timeout=600) for proc in procs]
    for proc, (_, err) in zip(procs, outputs):
        assert proc.returncode == 0, err[-3000:]
    events = [json.loads(line) for out, _ in outputs for line in out.splitlines()]
    forks = [e for e in events if "fork" in e]
    looks = [e for e in events if "look" in e]
    assert len(forks) >= WRITERS and sum(len(e["ids"]) for e in events if "add" in e) > WRITERS * 10

    with Store.open(store_url) as store:
        final = {b.name: [t for t in store.visible_trials(b.name)] for b in store.list_branches()}
        for fork in forks:
            inherited = [t.id for t in final[fork["fork"]] if t.branch != fork["fork"]]
            assert inherited == fork["inherited"], f"branch {fork['fork']} inherited trials committed after its fork"
            assert len(inherited) == fork["visible_at_fork"]
        for look in looks:
            count = sum(1 for t in final[look["look"]] if t.id <= look["watermark"])
            assert count == look["count"], f"branch {look['look']} up to trial {look['watermark']} changed after it was read"
        with store.engine.connect() as conn:
            rows = [visibility.BranchRow(r.id, r.name, r.parent_id, r.fork_point) for r in store._branches(conn)]  # noqa: SLF001
            trials = conn.execute(Trial.__table__.select().with_only_columns(Trial.id, Trial.branch_id)).all()
        for name, visible in final.items():
            chain = visibility.chain(rows, name)
            assert [t.id for t in visible] == sorted(t.id for t in trials if visibility.sees(chain, t.branch_id, t.id))
