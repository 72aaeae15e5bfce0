"""Generate the CLI reference (docs/cli.md) from the registered commands.

    python -m llcps.cli.docs > docs/cli.md

``tests/test_docs.py`` fails when the file and the command tree disagree.
"""

from __future__ import annotations

from typing import Any, Iterator

import typer

HEADER = """# CLI reference

Generated from the command tree by `python -m llcps.cli.docs > docs/cli.md`; a test keeps it in sync.
The global options `--db`, `--branch` and `--quiet` go before or after the command:
`llcps --db runs.db inspect trials --branch exp`.
With `--json` a command prints exactly one JSON document on stdout; messages and progress go to stderr.
Every error, a mistyped option included, prints `error: ...` and `hint: ...` on stderr and
exits 2; commands that report a result say what their exit codes 0, 1 and 130 mean
(130: Ctrl-C or SIGTERM). `LLCPS_DB_TIMEOUT` (seconds, default 30) bounds the wait for a
database server to answer and for a lock another process holds; `LLCPS_DB_STATEMENT_TIMEOUT`
(default 3600, 0: none) one PostgreSQL statement (docs/store.md).
`llcps --version` prints the version; `llcps --install-completion` installs shell completion.

An option name means the same in every command: `--seed` seeds the command's own random
choices and is recorded with its run, `--model-seed` seeds the world models; `--limit N`
is how many rows to show, `--trials N` / `--seeds N` / `--budget N` how many to make;
`--out FILE` is a file, `--out-dir DIR` a directory; `--scenario`, `--source`,
`--episode` and `--run` filter.

Long commands (`pretrain`, `solve`, `replay`, `inspect model`, `scenario check`,
`scenario render`, `experiment run`, `experiment report`, `db upgrade`, `db compact`,
`bench`) show their phase, counts, elapsed time and an ETA on stderr: on a terminal a
live display; otherwise (a pipe, a file, CI, `nohup`) plain lines, none in the first
interval, then a heartbeat at most every 5 s (`LLCPS_HEARTBEAT_SECONDS`) and a line when
a phase starts and ends:

```
$ llcps pretrain --trials 30 --seed 1 --create 2>&1 | cat
llcps pretrain [0:00:05] random interactions: 5/30 (17%), eta 0:00:14
llcps pretrain [0:00:10] random interactions: 18/30 (60%), eta 0:00:06
llcps pretrain [0:00:15] random interactions: 26/30 (87%), eta 0:00:02
llcps pretrain [0:00:16] random interactions: done in 0:00:13, 30/30
llcps pretrain [0:00:16] fitting world model nn: started
llcps pretrain [0:00:21] fitting world model nn: 0/2 (0%), eta unknown
llcps pretrain [0:00:26] fitting world model nb: 1/2 (50%), eta 0:00:11
llcps pretrain [0:00:31] fitting world models: done in 0:00:14, 2/2
llcps pretrain [0:00:31] finished
```

`--quiet` (`-q`, env `LLCPS_QUIET`) silences progress and messages; errors, warnings,
results said on stderr (`replay`'s match, `scenario check`'s failed properties, what a
dry run would do) and stdout (`--json` included) are unchanged.
"""


def _renamed_section() -> str:
    from llcps.cli._conventions import RENAMED_OPTIONS

    rows = "".join(
        f"| `llcps {command}` | `{old}` | `{new}` |\n" for command, names in RENAMED_OPTIONS.items() for old, new in names.items()
    )
    return (
        "\n## Renamed options\n\nThe old spellings still work for one release: they are hidden from `--help` "
        "and print a deprecation line on stderr.\n\n| command | old | new |\n|---|---|---|\n" + rows
    )


def walk(command: Any, ctx: Any) -> Iterator[tuple[Any, Any]]:
    """Every (command, context) of the tree, depth first, in registration order."""
    yield command, ctx
    for name, sub in getattr(command, "commands", {}).items():
        if not getattr(sub, "hidden", False):
            yield from walk(sub, sub.context_class(sub, info_name=name, parent=ctx))


def command_tree() -> Any:
    """The click command behind the ``llcps`` typer app."""
    from llcps.cli.main import app

    return typer.main.get_command(app)


def iter_commands() -> Iterator[tuple[Any, Any]]:
    """(command, context) for ``llcps`` and every subcommand."""
    root = command_tree()
    yield from walk(root, root.context_class(root, info_name="llcps"))


def _example_text(epilog: str) -> list[str]:
    """The example lines of an epilog as written (comments kept)."""
    from llcps.cli._conventions import EXAMPLES_HEADING

    block = epilog.split(EXAMPLES_HEADING, 1)[1]
    return [line.strip() for line in block.splitlines() if line.strip() and line.strip() != "\b"]


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render() -> str:
    """The whole reference as Markdown."""
    from llcps.cli._conventions import example_lines

    parts = [HEADER, _renamed_section()]
    for command, ctx in iter_commands():
        parts.append(f"\n## `{ctx.command_path}`\n")
        parts.append(f"\n{(command.help or '').strip()}\n")
        usage = " ".join([ctx.command_path, *command.collect_usage_pieces(ctx)])
        parts.append(f"\n```\n{usage}\n```\n")
        records = [p.get_help_record(ctx) for p in command.get_params(ctx)]
        rows = [r for r in records if r is not None and r[0] != "--help"]
        if rows:
            parts.append("\n| argument / option | help |\n|---|---|\n")
            parts.extend(f"| `{_cell(name)}` | {_cell(help_text)} |\n" for name, help_text in rows)
        examples = example_lines(getattr(command, "epilog", None))
        if examples:
            parts.append("\nExamples:\n\n```\n" + "\n".join(_example_text(command.epilog)) + "\n```\n")
        subcommands = getattr(command, "commands", {})
        if subcommands:
            parts.append("\n| command | what it does |\n|---|---|\n")
            parts.extend(
                f"| `{ctx.command_path} {name}` | {_cell(sub.get_short_help_str(limit=300))} |\n"
                for name, sub in subcommands.items()
            )
    return "".join(parts)


if __name__ == "__main__":
    print(render(), end="")
