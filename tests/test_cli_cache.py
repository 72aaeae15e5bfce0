"""``llcps cache``: status, bound and pruning of the physics cache from the command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_physics_cache import RESULT, SCENE, SETTINGS, SPEC, STATE
from typer.testing import CliRunner

from llcps.cli.cache import parse_size
from llcps.cli.main import app
from llcps.sim.cache import trial_key
from llcps.store import Store
from llcps.store import physics_cache as pc


def _llcps(db: Path, *args: str):  # noqa: ANN202 - click's Result
    return CliRunner().invoke(app, ["--db", str(db), "cache", *args])


@pytest.mark.parametrize(("text", "size"), [("0", 0), ("500MB", 500 * 10**6), ("2 GiB", 2 << 30), ("1.5kb", 1500), ("12", 12)])
def test_sizes_parse(text: str, size: int) -> None:
    assert parse_size(text) == size


def test_status_limit_and_prune(tmp_path: Path) -> None:
    db = tmp_path / "c.db"
    with Store.open(str(db), create=True) as store:
        cache = pc.StorePhysicsCache(store.engine)
        for steps in range(3):
            cache.put(trial_key(SETTINGS, SCENE, STATE, SPEC, steps), RESULT, STATE)
        (tmp_path / "a-file").write_bytes(b"")  # the key's directory is a file: no secret, no seal
        unsealed = pc.StorePhysicsCache(store.engine, key_file=tmp_path / "a-file" / "key")
        unsealed.put(trial_key(SETTINGS, SCENE, STATE, SPEC, 3), RESULT, STATE)
    status = json.loads(_llcps(db, "status", "--json").stdout)
    assert status["entries"] == 4 and status["max_bytes"] == pc.DEFAULT_MAX_BYTES and status["bytes"] > 0
    assert status["sealed"] == 3
    assert _llcps(db, "limit", "1MB").exit_code == 0
    assert json.loads(_llcps(db, "status", "--json").stdout)["max_bytes"] == 10**6
    dry = json.loads(_llcps(db, "prune", "--to", "0", "--dry-run", "--json").stdout)
    assert (dry["removed"], dry["dry_run"]) == (4, True)
    done = _llcps(db, "prune", "--to", "0", "--json")
    assert done.exit_code == 0 and json.loads(done.stdout)["removed"] == 4
    assert json.loads(_llcps(db, "status", "--json").stdout)["entries"] == 0
    bad = _llcps(db, "prune", "--to", "lots")
    assert bad.exit_code == 2 and "error: not a size" in bad.stderr and "hint:" in bad.stderr
