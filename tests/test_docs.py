"""Every command has help, and docs/cli.md is the generated reference of the registered commands."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from llcps.cli.docs import iter_commands, render
from llcps.cli.main import app

DOCS = Path(__file__).parents[1] / "docs"
COMMANDS = [ctx.command_path.split()[1:] for _, ctx in iter_commands()]


def test_cli_reference_is_in_sync() -> None:
    assert (DOCS / "cli.md").read_text(encoding="utf-8") == render(), "regenerate: python -m llcps.cli.docs > docs/cli.md"


def test_reference_lists_every_command() -> None:
    text = render()
    for path in COMMANDS:
        assert f"## `{' '.join(['llcps', *path])}`" in text
    assert ["db", "init"] in COMMANDS and ["inspect", "trials"] in COMMANDS


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "llcps")
def test_every_command_and_parameter_has_help(path: list[str]) -> None:
    command, ctx = next((c, x) for c, x in iter_commands() if x.command_path.split()[1:] == path)
    assert (command.help or "").strip(), f"{ctx.command_path} has no help text"
    for param in command.get_params(ctx):
        assert (getattr(param, "help", None) or "").strip(), f"{ctx.command_path}: {param.name} has no help text"
    result = CliRunner().invoke(app, [*path, "--help"])
    assert result.exit_code == 0 and "Usage:" in result.stdout


def test_store_guide_covers_branches_postgres_and_durability() -> None:
    guide = (DOCS / "store.md").read_text(encoding="utf-8")
    for phrase in ("llcps db branch", "--at pretrain", "postgresql+psycopg://", "kill -9", "synchronous=NORMAL", "llcps db upgrade"):
        assert phrase in guide, phrase
