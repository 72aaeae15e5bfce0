"""CLI conventions: --version, an Examples section in every command's help whose
examples parse, one meaning per option name, deprecated spellings, shell completion."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from typer.core import TyperGroup
from typer.testing import CliRunner

import llcps
from llcps.cli._conventions import RENAMED_OPTIONS, example_lines, rewrite_renamed
from llcps.cli.docs import command_tree, iter_commands
from llcps.cli.main import app

runner = CliRunner()
COMMANDS = [(ctx.command_path, command) for command, ctx in iter_commands()]
SCRIPT = Path(sys.executable).with_name("llcps")


def test_version_prints_the_package_version() -> None:
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.stdout.startswith(f"llcps {llcps.__version__}")


def _commands_of(line: str) -> list[list[str]]:
    """The llcps invocations of an example line (``&&`` chains split, redirections cut)."""
    out = []
    for part in line.split("&&"):
        words = shlex.split(part.split(" > ")[0].split(" | ")[0])
        assert words and words[0] == "llcps", f"example does not start with llcps: {line!r}"
        out.append(words[1:])
    return out


def _parse(args: list[str]) -> tuple[str, list[str]]:
    """Parse an invocation through the command tree as click would (raising a usage error on
    an unknown option or a bad value); returns the leaf's command path and its arguments."""
    root = command_tree()
    ctx = root.make_context("llcps", list(args))
    command = root
    rest: list[str] = []
    while isinstance(command, TyperGroup):
        rest = [*ctx._protected_args, *ctx.args]
        name, command, rest = TyperGroup.resolve_command(command, ctx, rest)  # as written: no rewriting
        ctx = command.make_context(name, list(rest), parent=ctx)
    return ctx.command_path, rest


@pytest.mark.parametrize(("path", "command"), COMMANDS, ids=[p for p, _ in COMMANDS])
def test_every_command_has_examples_that_parse(path: str, command: object) -> None:
    lines = example_lines(command.epilog)
    assert lines, f"{path} has no Examples section"
    leaves = []
    for line in lines:
        for args in _commands_of(line):
            if args == ["--version"]:
                leaves.append("llcps")
                continue
            leaf, rest = _parse(args)
            leaves.append(leaf)
            deprecated = RENAMED_OPTIONS.get(leaf.removeprefix("llcps").strip(), {})
            assert not [a for a in rest if a.split("=")[0] in deprecated], f"{line!r} uses a deprecated spelling"
    assert any(leaf.startswith(path) for leaf in leaves), f"no example of {path} runs it: {lines}"
    help_text = runner.invoke(app, [*path.split()[1:], "--help"]).stdout
    assert "Examples:" in help_text and lines[0] in help_text


# Option names whose meaning is fixed across commands, and what every use must look like.
def _option_uses(name: str) -> list[tuple[str, object]]:
    return [
        (path, p)
        for path, command in COMMANDS
        for p in command.params  # type: ignore[attr-defined]
        if getattr(p, "param_type_name", "") == "option" and name in p.opts
    ]


def test_one_meaning_per_option_name() -> None:
    def info(option: object) -> object:
        return option.type_descriptor.parameter_info  # type: ignore[attr-defined]

    def annotation(option: object) -> object:
        return option.type_descriptor.annotation  # type: ignore[attr-defined]

    for path, option in _option_uses("--out"):
        assert option.metavar == "FILE" and info(option).dir_okay is False, f"{path} --out is not a file"  # type: ignore[attr-defined]
    for path, option in _option_uses("--out-dir"):
        assert option.metavar == "DIR" and info(option).file_okay is False, path  # type: ignore[attr-defined]
    for path, option in _option_uses("--gif"):
        assert option.metavar == "FILE" and annotation(option) is Path, path  # type: ignore[attr-defined]
    for name in ("--limit", "--trials", "--seeds", "--budget"):
        uses = _option_uses(name)
        assert uses, name
        for path, option in uses:
            assert option.metavar == "N" and annotation(option) is int, f"{path} {name}"  # type: ignore[attr-defined]
    seeds = _option_uses("--seed")
    assert {p for p, _ in seeds} >= {"llcps pretrain", "llcps solve", "llcps inspect model"}
    for path, option in seeds:
        assert "run seed" in (option.help or "").lower(), f"{path} --seed: {option.help}"  # type: ignore[attr-defined]
    model_seeds = _option_uses("--model-seed")
    assert {p for p, _ in model_seeds} == {"llcps pretrain", "llcps solve", "llcps inspect model"}
    for path, option in model_seeds:
        text = (option.help or "").lower()  # type: ignore[attr-defined]
        assert "seed of the" in text and ("world model" in text or "fitted models" in text), path
    declared = {o for _, command in COMMANDS for p in command.params for o in getattr(p, "opts", ())}  # type: ignore[attr-defined]
    for command, names in RENAMED_OPTIONS.items():
        for old, new in names.items():
            path = f"llcps {command}"
            opts = {o for p, c in COMMANDS if p == path for q in c.params for o in getattr(q, "opts", ())}  # type: ignore[attr-defined]
            assert new in opts and old not in opts, f"{path}: {old} -> {new}"
    assert "--top" not in declared and "--n" not in declared


def test_renamed_spellings_are_rewritten_with_a_warning(capsys: pytest.CaptureFixture[str]) -> None:
    assert rewrite_renamed("pretrain", ["--n", "5", "--seed=1", "--n=7", "--", "--n"]) == ["--trials", "5", "--seed=1", "--trials=7", "--", "--n"]
    assert capsys.readouterr().err.count("`llcps pretrain --n` is deprecated, use --trials") == 2
    assert rewrite_renamed("db export", ["--out", "x.csv"]) == ["--out", "x.csv"]  # --out is a file there, not renamed


def _small_results(path: Path) -> Path:
    """Two seeds of one cell, update and reset, written as a results CSV."""
    from llcps.experiments.design import PAPER_SCENARIOS, Cell, Sequence
    from llcps.analysis.results import ResultsTable
    from llcps.experiments.rows import ResultRow

    rows = []
    for seed in (0, 1):
        for condition in ("update", "reset"):
            seq = Sequence("smoke", Cell("nb", "most-changes", 4, condition), seed)
            for i, scenario in enumerate(PAPER_SCENARIOS):
                trials = 3 + i + seed + (condition == "reset")
                rows.append(
                    ResultRow("smoke", "nb", "most-changes", 4, condition, seed, scenario, trials < 5, trials,
                              0.1 * trials, 0.2 * trials, len(rows) + 1, seq.episode_branch(scenario))
                )  # fmt: skip
    return ResultsTable(rows).write_csv(path)


def test_a_deprecated_spelling_still_works_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "report"
    table = _small_results(tmp_path / "results.csv")
    result = runner.invoke(app, ["experiment", "report", str(table), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "`llcps experiment report --out` is deprecated, use --out-dir" in result.stderr
    assert (out / "report.md").is_file() and (out / "results.csv").is_file()


def test_shell_completion_completes_commands() -> None:
    env = {**os.environ, "_LLCPS_COMPLETE": "complete_bash", "COMP_WORDS": "llcps inspect ", "COMP_CWORD": "2"}
    done = subprocess.run([str(SCRIPT)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert {"trials", "runs", "episodes", "model", "knowledge"} <= set(done.stdout.split())
    shown = runner.invoke(app, ["--help"]).stdout
    assert "--install-completion" in shown


def test_the_first_line_names_the_command() -> None:
    """On a terminal the console script says `llcps <command>: starting` before loading anything."""
    from llcps.cli.entry import _command_words

    assert _command_words(["--db", "x.db", "--branch", "exp", "solve", "scenario2", "--budget", "5"]) == "solve scenario2"
    assert _command_words(["inspect", "model", "--scenario", "s"]) == "inspect model"
    assert _command_words(["--db=x.db", "pretrain", "--trials", "3"]) == "pretrain"
    assert _command_words([]) == ""
