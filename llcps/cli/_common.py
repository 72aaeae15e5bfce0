"""What every command module shares: the app factory, the global context, store
opening, output helpers and the error wrapper.

Output rules: data goes to stdout (a table, or with ``--json`` exactly one JSON
document); messages and progress go to stderr. A :class:`~llcps.errors.LlcpsError`
anywhere below the root command becomes ``error: ...`` / ``hint: ...`` on stderr
and its exit code, never a traceback.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from enum import Enum
from typing import Annotated, Any, Iterable

import typer
from rich.console import Console
from rich.table import Table
from llcps.cli._conventions import ConventionGroup
from llcps.errors import LlcpsError
from llcps.store import Store

#: Human messages and progress.
err_console = Console(stderr=True, highlight=False, soft_wrap=True)
#: Tables for people (the data of commands run without --json); wide when piped.
out_console = Console(highlight=False, width=None if sys.stdout.isatty() else 200)

DEFAULT_DB = "llcps.db"

JsonFlag = Annotated[bool, typer.Option("--json", help="Print one JSON document on stdout instead of text.")]
YesFlag = Annotated[bool, typer.Option("--yes", help="Really do it; without it, only report what would change.")]


def report_error(exc: LlcpsError) -> None:
    """Print a project error the one way the CLI does."""
    typer.echo(f"error: {exc.message}", err=True)
    if exc.hint:
        typer.echo(f"hint: {exc.hint}", err=True)


class LlcpsGroup(ConventionGroup):
    """The root command group: turns project errors into one line and an exit code."""

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except LlcpsError as exc:
            report_error(exc)
            raise typer.Exit(exc.exit_code) from None


def new_app(help: str, **kwargs: Any) -> typer.Typer:  # noqa: A002 - typer's own name
    """A Typer app with the project's settings (plain help, no tracebacks; completion
    options only where the root app asks for them)."""
    settings: dict[str, Any] = {
        "help": help,
        "no_args_is_help": True,
        "rich_markup_mode": None,
        "pretty_exceptions_enable": False,
        "add_completion": False,
        "cls": ConventionGroup,
    }
    settings.update(kwargs)
    return typer.Typer(**settings)


def choice_enum(name: str, values: Iterable[str]) -> type[Enum]:
    """A str Enum for a typer choice, built from a registry tuple (the one source of truth)."""
    return Enum(name, {value.replace("-", "_"): value for value in values}, type=str)  # type: ignore[return-value]


@dataclass
class CliContext:
    """Global options, handed to every subcommand through ``ctx.obj``."""

    db: str = DEFAULT_DB
    branch: str | None = None


def cli_context(ctx: typer.Context) -> CliContext:
    obj = ctx.find_object(CliContext)
    return obj if obj is not None else CliContext()


def open_store(ctx: typer.Context, *, create: bool = False, allow_outdated: bool = False) -> Store:
    """Open the store named by ``--db`` (see :meth:`Store.open`)."""
    return Store.open(cli_context(ctx).db, create=create, allow_outdated=allow_outdated)


def selected_branch(ctx: typer.Context) -> str | None:
    """The ``--branch`` option (None: the store's current branch)."""
    return cli_context(ctx).branch


def print_json(data: Any) -> None:
    """Write one JSON document to stdout."""
    sys.stdout.write(json.dumps(data, indent=2, default=str) + "\n")
    sys.stdout.flush()


def message(text: str) -> None:
    """A line for people, on stderr."""
    err_console.print(text, markup=False)


def print_table(title: str | None, columns: Iterable[str], rows: Iterable[Iterable[Any]], *, show_header: bool = True) -> None:
    """A rich table on stdout."""
    table = Table(title=title, show_header=show_header)
    for column in columns:
        table.add_column(column)
    for row in rows:
        table.add_row(*("" if v is None else str(v) for v in row))
    out_console.print(table)
