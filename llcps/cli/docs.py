"""Generate the CLI reference (docs/cli.md) from the registered commands.

    python -m llcps.cli.docs > docs/cli.md

``tests/test_docs.py`` fails when the file and the command tree disagree.
"""

from __future__ import annotations

from typing import Any, Iterator

import typer

HEADER = """# CLI reference

Generated from the command tree by `python -m llcps.cli.docs > docs/cli.md`; a test keeps it in sync.
The global options `--db` and `--branch` go before or after the command:
`llcps --db runs.db inspect trials --branch exp`.
With `--json` a command prints exactly one JSON document on stdout; messages go to stderr.
Every error, a mistyped option included, prints `error: ...` and `hint: ...` on stderr and
exits 2; commands that report a result say what their exit codes 0, 1 and 130 mean.
"""


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


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render() -> str:
    """The whole reference as Markdown."""
    parts = [HEADER]
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
