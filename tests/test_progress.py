"""Progress off a terminal (plain heartbeat lines), --quiet, and the scenario check's
estimate of its sweep. The terminal display is tested in tests/test_workbench.py."""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from llcps.cli._common import hoist_global_options
from llcps.cli._progress import HEARTBEAT_ENV, HeartbeatLines, heartbeat_seconds
from llcps.cli.main import app
from llcps.errors import LlcpsError

runner = CliRunner()


class Clock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _heartbeat(first_phase: str = "loading the simulator", every: float = 5) -> tuple[HeartbeatLines, io.StringIO, Clock]:
    clock, out = Clock(), io.StringIO()
    return HeartbeatLines("pretrain", first_phase, stream=out, every=every, clock=clock), out, clock


def test_heartbeat_lines_name_the_phase_counts_elapsed_and_eta() -> None:
    beat, out, clock = _heartbeat()
    clock.now = 102
    beat("random interactions", 1, 30)  # a phase inside the first interval: nothing yet
    clock.now = 104.9
    beat.tick()
    assert out.getvalue() == ""
    clock.now = 106
    beat("random interactions", 7, 30)
    beat.tick()  # 6 trials in 4 s since the phase's first count: 23 left take 15.3 s
    clock.now = 108
    beat.tick()  # not due: the last line was 2 s ago
    clock.now = 111
    beat.tick()  # no trial since: the rate falls, the ETA grows
    clock.now = 111.5
    beat("random interactions", 30, 30)
    clock.now = 112
    beat("fitting world model nb", 0, 2)  # a new count: the phase ends, the next starts
    clock.now = 113
    beat("fitting world model nn", 1, 2)  # the same count going on: a step inside the phase
    clock.now = 118
    beat.tick()
    clock.now = 119
    beat.finish()
    assert out.getvalue().splitlines() == [
        "llcps pretrain [0:00:06] random interactions: 7/30 (23%), eta 0:00:16",
        "llcps pretrain [0:00:11] random interactions: 7/30 (23%), eta 0:00:35",
        "llcps pretrain [0:00:12] random interactions: done in 0:00:10, 30/30",
        "llcps pretrain [0:00:12] fitting world model nb: started",
        "llcps pretrain [0:00:18] fitting world model nn: 1/2 (50%), eta 0:00:06",
        "llcps pretrain [0:00:19] fitting world model nn: done in 0:00:07, 1/2",
        "llcps pretrain [0:00:19] finished",
    ]


def test_heartbeat_without_counts_says_how_long_the_phase_runs() -> None:
    beat, out, clock = _heartbeat("compacting the store")
    clock.now = 107
    beat.tick()
    beat.note("rewriting the file")  # a step inside the phase: shown by the next heartbeat
    clock.now = 113
    beat.tick()
    assert out.getvalue().splitlines() == [
        "llcps pretrain [0:00:07] compacting the store: running for 0:00:07",
        "llcps pretrain [0:00:13] rewriting the file: running for 0:00:13",
    ]


def test_a_command_done_within_the_first_interval_prints_no_progress() -> None:
    beat, out, clock = _heartbeat()
    beat("random interactions", 3, 3)
    clock.now = 104
    beat.finish()
    assert out.getvalue() == ""


def test_the_heartbeat_interval_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(HEARTBEAT_ENV, "0.5")
    assert heartbeat_seconds() == 0.5
    monkeypatch.delenv(HEARTBEAT_ENV)
    assert heartbeat_seconds() == 5.0
    for bad in ("0", "-1", "soon", "nan"):
        monkeypatch.setenv(HEARTBEAT_ENV, bad)
        with pytest.raises(LlcpsError, match=HEARTBEAT_ENV):
            heartbeat_seconds()
    db = tmp_path / "p.db"
    result = runner.invoke(app, ["--db", str(db), "pretrain", "--trials", "2", "--create"], env={HEARTBEAT_ENV: "soon"})
    assert result.exit_code == 2 and [line.split(":", 1)[0] for line in result.stderr.splitlines()] == ["error", "hint"]
    assert not db.exists()


def _llcps(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """The CLI as a script runs it under CI: stdout and stderr are pipes, not a terminal."""
    return subprocess.run(
        [sys.executable, "-m", "llcps.cli.main", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        timeout=600,
        env={**os.environ, **env},
    )


def test_a_piped_pretrain_prints_heartbeat_lines_with_an_eta(tmp_path: Path) -> None:
    done = _llcps(
        "--db", str(tmp_path / "p.db"), "pretrain", "--trials", "6", "--model", "nb", "--create", "--json", env={HEARTBEAT_ENV: "0.1"}
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["trials"] == 6
    lines = done.stderr.splitlines()
    assert lines and all(re.match(r"llcps pretrain \[\d+:\d\d:\d\d\] ", line) for line in lines), done.stderr
    counted = [line for line in lines if re.search(r"random interactions: [1-6]/6 \(\d+%\), eta \d+:\d\d:\d\d$", line)]
    assert counted, done.stderr
    assert any(line.endswith("random interactions: started") for line in lines), done.stderr
    assert re.search(r"random interactions: done in \d+:\d\d:\d\d, 6/6$", done.stderr, re.MULTILINE), done.stderr
    assert lines[-1].endswith("] finished")


def test_quiet_prints_nothing_on_stderr_but_the_result_and_errors(tmp_path: Path) -> None:
    db = tmp_path / "q.db"
    done = _llcps("--db", str(db), "pretrain", "--trials", "2", "--model", "nb", "--create", "--json", "--quiet", env={HEARTBEAT_ENV: "0.1"})
    assert done.returncode == 0 and done.stderr == ""
    assert json.loads(done.stdout)["trials"] == 2
    table = _llcps("--db", str(db), "pretrain", "--trials", "1", "--model", "nb", env={HEARTBEAT_ENV: "0.1", "LLCPS_QUIET": "1"})
    assert table.returncode == 0 and table.stderr == "" and "pretraining trials" in table.stdout
    failed = _llcps("-q", "--db", str(tmp_path / "absent.db"), "pretrain", "--trials", "1", env={HEARTBEAT_ENV: "0.1"})
    assert failed.returncode == 2 and [line.split(":", 1)[0] for line in failed.stderr.splitlines()] == ["error", "hint"]


def test_quiet_silences_messages_but_keeps_what_a_dry_run_would_do(tmp_path: Path) -> None:
    db = str(tmp_path / "m.db")
    assert "store ready" in runner.invoke(app, ["--db", db, "db", "init"]).stderr
    assert runner.invoke(app, ["--db", db, "db", "init"], env={"LLCPS_QUIET": "1"}).stderr == ""
    made = runner.invoke(app, ["--db", db, "db", "branch", "exp", "--quiet"])
    assert made.exit_code == 0 and made.stderr == ""
    dry = runner.invoke(app, ["--db", db, "db", "delete", "exp", "--quiet"])
    assert dry.exit_code == 0 and "nothing changed (rerun with --yes" in dry.stderr
    gone = runner.invoke(app, ["--db", db, "db", "delete", "exp", "--yes", "--quiet"])
    assert gone.exit_code == 0 and gone.stderr == ""


def test_quiet_after_the_command_is_the_global_flag() -> None:
    assert hoist_global_options(["pretrain", "--trials", "3", "--quiet"]) == ["--quiet", "pretrain", "--trials", "3"]
    assert hoist_global_options(["solve", "-q", "scenario2", "--", "--quiet"]) == ["-q", "solve", "scenario2", "--", "--quiet"]


def test_the_sweep_estimate_is_candidates_times_a_time_per_trial() -> None:
    from llcps.cli.scenario import about, sweep_estimate_text
    from llcps.cps.check import TYPICAL_SECONDS_PER_TRIAL, SweepEstimate

    cheap_start = SweepEstimate(variant=0, candidates=467, timed=3, measured=0.02, quick=False)
    assert cheap_start.seconds_per_trial == TYPICAL_SECONDS_PER_TRIAL == 0.5 and cheap_start.seconds == 233.5
    slow = SweepEstimate(variant=2, candidates=100, timed=3, measured=2.0, quick=True)
    assert slow.seconds == 200.0
    assert (about(30), about(233.5), about(4670)) == ("under a minute", "~4 min", "~1 h 18 min")
    text = sweep_estimate_text(cheap_start, range(0, 5))
    assert "467 candidates x ~0.5 s a trial (the first 3 took 0.02 s each" in text
    assert text.endswith("the sweep may take ~4 min; 5 variants, if alike: ~19 min")
    assert sweep_estimate_text(slow, range(0, 5)).endswith("~3 min at most (--quick stops at the first resolving candidate)")


def test_quiet_drops_the_early_starting_line_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    from llcps.cli.entry import _quiet

    monkeypatch.delenv("LLCPS_QUIET", raising=False)
    assert _quiet(["--db", "x.db", "pretrain", "-q"]) and _quiet(["--quiet", "solve", "scenario2"])
    assert not _quiet(["solve", "scenario2"]) and not _quiet(["solve", "--", "--quiet"])
    monkeypatch.setenv("LLCPS_QUIET", "yes")
    assert _quiet(["solve", "scenario2"])
