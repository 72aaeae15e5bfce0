"""The conventions every command follows: an Examples section in its help, one meaning
per option name, and old option spellings kept as deprecated aliases for one release.

Option names mean the same thing in every command:

* ``--seed N``: the seed of this command's own random choices, recorded with its run;
  ``--model-seed N``: the seed of the world models it fits or loads.
* ``--limit N``: how many rows to show; ``--trials N``, ``--seeds N``, ``--budget N``:
  how many of those things to make.
* ``--out FILE``: a file to write; ``--out-dir DIR``: a directory to write into;
  ``--gif FILE``: a GIF to render.
* ``--scenario``, ``--source``, ``--episode``, ``--run``: filters (or the one to act on).

A renamed option is listed in :data:`RENAMED_OPTIONS`; the old spelling still works for
one release, is hidden from ``--help`` and prints a deprecation line on stderr.
"""

from __future__ import annotations

from typing import Any, Mapping

import typer
from typer.core import TyperGroup

#: Old spelling -> new spelling, per command path (without ``llcps``).
RENAMED_OPTIONS: Mapping[str, Mapping[str, str]] = {
    "pretrain": {"--n": "--trials"},
    "inspect model": {"--top": "--limit"},
    "experiment run": {"--out": "--out-dir"},
    "experiment report": {"--out": "--out-dir"},
}

EXAMPLES_HEADING = "Examples:"


def examples(*lines: str) -> str:
    """The Examples section of a command's help (its epilog), one command line per example.

    A line may end with ``# what it does``; click keeps the block as written (``\\b``).
    """
    body = "\n".join(f"  {line}" for line in lines)
    return f"{EXAMPLES_HEADING}\n\n\b\n{body}"


def example_lines(epilog: str | None) -> list[str]:
    """The example command lines of an epilog written by :func:`examples` (comments dropped)."""
    if not epilog or EXAMPLES_HEADING not in epilog:
        return []
    block = epilog.split(EXAMPLES_HEADING, 1)[1]
    lines = []
    for raw in block.splitlines():
        text = raw.strip()
        if not text or text == "\b":
            continue
        lines.append(text.split("  #", 1)[0].strip())
    return lines


def command_key(ctx: Any, name: str) -> str:
    """``"experiment run"`` for the command ``name`` under ``ctx`` (the program name dropped)."""
    return " ".join([*ctx.command_path.split()[1:], name])


def rewrite_renamed(key: str, args: list[str], *, warn: bool = True) -> list[str]:
    """Replace old option spellings of command ``key`` in ``args``, saying so on stderr."""
    renamed = RENAMED_OPTIONS.get(key)
    if not renamed:
        return args
    out: list[str] = []
    for index, arg in enumerate(args):
        if arg == "--":
            return out + args[index:]
        name, eq, value = arg.partition("=")
        new = renamed.get(name)
        if new is None:
            out.append(arg)
            continue
        if warn:
            typer.echo(
                f"warning: `llcps {key} {name}` is deprecated, use {new} (the old spelling goes in the next release)",
                err=True,
            )
        out.append(new + eq + value)
    return out


class ConventionGroup(TyperGroup):
    """A command group that accepts the deprecated spellings of its commands' options."""

    def resolve_command(self, ctx: Any, args: list[str]) -> tuple[str | None, Any, list[str]]:
        name, command, rest = super().resolve_command(ctx, args)
        if name is not None and command is not None and not isinstance(command, TyperGroup):
            rest = rewrite_renamed(command_key(ctx, name), rest, warn=not ctx.resilient_parsing)
        return name, command, rest
