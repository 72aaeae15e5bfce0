"""What every command module shares: the app factory, the global context, store
opening, output checks, output helpers and the error contract.

Output rules: data goes to stdout (a table, or with ``--json`` exactly one JSON
document); messages and progress go to stderr. ``--quiet`` silences progress and
:func:`message` lines, never :func:`notice` lines (a result said on stderr, a warning, a
failure), errors or stdout. Every error, argument parsing
included, becomes ``error: ...`` / ``hint: ...`` on stderr and exit code 2 (130 for
Ctrl-C), never a traceback (see :class:`LlcpsGroup`). Text from the store (branch
names, scenarios) is printed literally (:func:`literal`): never as rich markup, and a
control character (an ESC sequence, a newline) shows as its escape, ``\\x1b``, ``\\n``.
"""

from __future__ import annotations

import json
import os
import re
import signal
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from enum import Enum
from typing import Annotated, Any, Iterable, Iterator

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from llcps.cli._conventions import ConventionGroup
from llcps.errors import LlcpsError
from llcps.store import Store

try:  # recent typer carries its own copy of click, whose exceptions the parser raises
    from typer._click import exceptions as click_exceptions
    from typer._click.globals import get_current_context
except ImportError:  # pragma: no cover - older typer uses click itself
    from click import exceptions as click_exceptions
    from click import get_current_context

#: Human messages and progress.
err_console = Console(stderr=True, highlight=False, soft_wrap=True)
#: Tables for people (the data of commands run without --json); wide when piped.
out_console = Console(highlight=False, width=None if sys.stdout.isatty() else 200)

DEFAULT_DB = "llcps.db"

JsonFlag = Annotated[bool, typer.Option("--json", help="Print one JSON document on stdout instead of text.")]
YesFlag = Annotated[bool, typer.Option("--yes", help="Really do it; without it, only report what would change.")]
CreateFlag = Annotated[
    bool, typer.Option("--create", help="Create the store if --db names none yet (otherwise only `llcps db init` creates one).")
]


def terminate_like_interrupt() -> None:
    """Make SIGTERM (``kill``, a scheduler's stop, a container's shutdown) end a command
    the way Ctrl-C does: a ``KeyboardInterrupt`` where the command is, so its episode
    and run are marked ``interrupted``, completed work is kept and the exit code is 130."""

    def on_sigterm(signum: int, _frame: Any) -> None:
        signal.signal(signum, signal.SIG_DFL)  # a second SIGTERM ends the process at once
        raise KeyboardInterrupt(f"signal {int(signum)}")

    try:
        signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # pragma: no cover - not the main thread (an embedding program)
        pass


def report_error(exc: LlcpsError) -> None:
    """Print a project error the one way the CLI does: an ``error:`` and a ``hint:`` line."""
    typer.echo(f"error: {_one_line(exc.message)}", err=True)
    typer.echo(f"hint: {_one_line(exc.hint or 'see `llcps --help`')}", err=True)


def _one_line(text: str) -> str:
    return " ".join(printable(str(text), keep="\n\t").split())


def printable(text: str, *, keep: str = "") -> str:
    """``text`` with every character that is not printable (ESC, a newline, a NUL, a
    bidirectional override; those in ``keep`` excepted) written as its Python escape, so
    text from a store or a file cannot move the cursor, recolour the terminal or forge a line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() or c in keep else repr(c)[1:-1] for c in text)


#: Longest text a table cell shows (a name from a store may be any length).
MAX_CELL_CHARS = 240


def literal(text: object) -> str:
    """Text from the store or a file for a rich table: :func:`printable`, cut to
    :data:`MAX_CELL_CHARS` (ending in ``…``), and its markup escaped (``[bold]`` prints as written)."""
    shown = str(text)
    if len(shown) > MAX_CELL_CHARS:
        shown = shown[: MAX_CELL_CHARS - 1] + "…"
    shown = printable(shown)
    if len(shown) > MAX_CELL_CHARS:  # escapes lengthen it
        shown = shown[: MAX_CELL_CHARS - 1] + "…"
    return escape(shown)


_SUGGESTION = re.compile(r"\s*\(?(?:Did you mean|Possible options:) (.+?)\??\)?\s*$", re.IGNORECASE)


def usage_error(exc: Any) -> LlcpsError:
    """A click parsing error as a project error: its message, and a hint at the fix."""
    text = _one_line(exc.format_message())
    ctx = getattr(exc, "ctx", None)
    command = ctx.command_path if ctx is not None else "llcps"
    hint = f"see `{command} --help`"
    found = _SUGGESTION.search(text)
    if found:
        text = text[: found.start()].rstrip(" .")
        hint = f"did you mean {found.group(1)}? ({hint})"
    return LlcpsError(text[:1].lower() + text[1:], hint=hint)


#: click >= 8.2 reports a bare group (``llcps db``) as this usage error; older click exits 0 itself.
_NO_ARGS_IS_HELP: Any = getattr(click_exceptions, "NoArgsIsHelpError", ())


class LlcpsGroup(ConventionGroup):
    """The root command group: one error contract for everything below it.

    Every failure, argument parsing included, prints ``error: ...`` and ``hint: ...`` on
    stderr and exits 2 (``LlcpsError.exit_code``); Ctrl-C exits 130. An unexpected
    exception is reported the same way as an internal error (``LLCPS_DEBUG=1`` shows
    its traceback). The global ``--db`` and ``--branch`` may also follow the
    subcommand (:func:`hoist_global_options`).
    """

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None, standalone_mode: bool = True, **extra: Any) -> Any:  # type: ignore[override]  # noqa: E501
        code = self._run(args, prog_name, complete_var, extra)
        if not standalone_mode:
            return code
        sys.exit(code)

    def _run(self, args: Any, prog_name: str | None, complete_var: str | None, extra: dict[str, Any]) -> int:
        args = hoist_global_options(list(sys.argv[1:] if args is None else args))
        try:
            result = super().main(args=args, prog_name=prog_name, complete_var=complete_var, standalone_mode=False, **extra)
            return result if isinstance(result, int) else 0
        except click_exceptions.ClickException as exc:
            if isinstance(exc, _NO_ARGS_IS_HELP) and exc.ctx is not None:  # a bare group: its help, not an error
                typer.echo(exc.ctx.get_help())
                return 0
            report_error(usage_error(exc))
            return LlcpsError.exit_code
        except LlcpsError as exc:
            report_error(exc)
            return exc.exit_code
        except (typer.Abort, KeyboardInterrupt) as exc:
            typer.echo(f"error: interrupted{' by SIGTERM' if str(exc) == f'signal {int(signal.SIGTERM)}' else ''}", err=True)
            typer.echo("hint: completed work is kept; run the same command again to go on", err=True)
            return 130
        except Exception as exc:  # noqa: BLE001 - the contract: never a traceback
            if os.environ.get("LLCPS_DEBUG"):
                raise
            report_error(
                LlcpsError(
                    f"internal error: {type(exc).__name__}: {exc}",
                    hint="this is a bug in llcps; rerun with LLCPS_DEBUG=1 to see the traceback and report it",
                )
            )
            return LlcpsError.exit_code


#: Global options that may also follow the subcommand: ``llcps inspect trials --branch exp``.
GLOBAL_OPTIONS = ("--db", "--branch")
#: Global flags (no value) that may also follow the subcommand: ``llcps pretrain --quiet``.
GLOBAL_FLAGS = ("--quiet", "-q")


def hoist_global_options(args: list[str]) -> list[str]:
    """Move ``--db``/``--branch`` (and their values) and ``--quiet`` given after the
    subcommand to the front.

    Click only knows a group's options before its subcommand; moving them keeps one
    definition (with its environment variable) for both places. Tokens after ``--``
    are left alone; a later occurrence wins, as with any repeated option.
    """
    front: list[str] = []
    rest: list[str] = []
    i = 0
    while i < len(args):
        token = args[i]
        if token == "--":
            rest.extend(args[i:])
            break
        name = token.split("=", 1)[0]
        if token in GLOBAL_FLAGS:
            front.append(token)
        elif name in GLOBAL_OPTIONS:
            if "=" in token:
                front.append(token)
            elif i + 1 < len(args):
                front.extend(args[i : i + 2])
                i += 1
            else:
                rest.append(token)  # let click say that the value is missing
        else:
            rest.append(token)
        i += 1
    return front + rest


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


def comma_list(text: str | None) -> list[str] | None:
    """The names of an ``A,B`` option, blanks dropped (None: the option was not given)."""
    return None if text is None else [part.strip() for part in text.split(",") if part.strip()]


def choice_enum(name: str, values: Iterable[str]) -> type[Enum]:
    """A str Enum for a typer choice, built from a registry tuple (the one source of truth)."""
    return Enum(name, {value.replace("-", "_"): value for value in values}, type=str)  # type: ignore[return-value]


@dataclass
class CliContext:
    """Global options, handed to every subcommand through ``ctx.obj``."""

    db: str = DEFAULT_DB
    branch: str | None = None
    quiet: bool = False


def cli_context(ctx: typer.Context) -> CliContext:
    obj = ctx.find_object(CliContext)
    return obj if obj is not None else CliContext()


def quiet() -> bool:
    """Whether the command running now was given ``--quiet`` (or ``LLCPS_QUIET``).

    Read from the running command's context, so it holds for one invocation only;
    outside a command (a library caller, a test of the display) it is False.
    """
    ctx = get_current_context(silent=True)
    obj = ctx.find_object(CliContext) if ctx is not None else None
    return obj is not None and obj.quiet


def db_location(ctx: typer.Context) -> str:
    """The ``--db`` option: the store a job opens (a SQLite path or an SQLAlchemy URL)."""
    return cli_context(ctx).db


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
    """A line for people, on stderr, that ``--quiet`` silences: what was written where,
    what changed, what comes next."""
    if not quiet():
        err_console.print(printable(text, keep="\n"), markup=False)


def notice(text: str) -> None:
    """A line for people, on stderr, that ``--quiet`` keeps: part of a command's result
    (``match``, a failed property), a warning, or a task that failed."""
    err_console.print(printable(text, keep="\n"), markup=False)


#: Exit codes of a run of tasks (experiment run, life run): all done, a task failed, Ctrl-C.
EXIT_OK, EXIT_FAILED, EXIT_INTERRUPTED = 0, 1, 130


@contextmanager
def resumable(what: str) -> Iterator[None]:
    """A run of tasks that keeps every ``what`` imported: Ctrl-C says how to resume, exit 130."""
    try:
        yield
    except KeyboardInterrupt:
        notice(f"interrupted: every {what} imported so far is kept; run the same command to resume")
        raise typer.Exit(EXIT_INTERRUPTED) from None


def settle_run(summary: Any) -> None:
    """Say how a run of tasks ended (a ``RunSummary``): exit 130 when it was interrupted,
    else one line per failed task (the caller reports and exits)."""
    if summary.status == "interrupted":
        notice(f"interrupted: {summary.done} task(s) imported by this run are kept; run the same command to resume")
        raise typer.Exit(EXIT_INTERRUPTED)
    for label, error in summary.failed:
        notice(f"task {label} failed: {error}")


def human_bytes(n: int) -> str:
    """A size for people: ``1.5 GB``, ``161.0 MB``, ``12 B``."""
    for unit, size in (("GB", 10**9), ("MB", 10**6), ("kB", 10**3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n} B"


def print_table(title: str | None, columns: Iterable[str], rows: Iterable[Iterable[Any]], *, show_header: bool = True) -> None:
    """A rich table on stdout."""
    table = Table(title=None if title is None else literal(title), show_header=show_header)
    for column in columns:
        table.add_column(literal(column))
    for row in rows:  # cells hold names from the store: never markup, never control characters
        table.add_row(*("" if v is None else literal(v) for v in row))
    out_console.print(table)
