"""The ``llcps`` console script: say something at once, then load the command tree.

Loading every command module (SQLAlchemy, numpy, the registries) takes a second or
more, several on a busy machine. On a terminal, a one-line ``llcps <command>:
starting`` appears first and is cleared once the commands are loaded; the command's
own progress display takes over from there. Piped output and ``--quiet`` (or
``LLCPS_QUIET``) get nothing extra.
"""

from __future__ import annotations

import os
import sys

_CLEAR_LINE = "\r\x1b[2K"
#: How click reads a true boolean from the environment (``LLCPS_QUIET=1``).
_TRUE = ("1", "true", "t", "yes", "y", "on")


def _command_words(argv: list[str]) -> str:
    """The command the arguments name, global options skipped (for the first line)."""
    words: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
            continue
        if arg in ("--db", "--branch"):
            skip = True
            continue
        if arg.startswith("-"):
            if words:
                break
            continue
        words.append(arg)
        if len(words) == 2:
            break
    return " ".join(words)


def _quiet(argv: list[str]) -> bool:
    """Whether the command line or the environment asks for ``--quiet``."""
    before = argv[: argv.index("--")] if "--" in argv else argv
    return any(a in ("--quiet", "-q") for a in before) or os.environ.get("LLCPS_QUIET", "").strip().lower() in _TRUE


def main() -> None:
    """Console-script entry point."""
    stream = sys.stderr
    early = stream.isatty() and not any(a in ("--help", "--version", "--show-completion") for a in sys.argv[1:])
    early = early and "_LLCPS_COMPLETE" not in os.environ  # shell completion wants stdout alone
    early = early and not _quiet(sys.argv[1:])
    if early:
        words = _command_words(sys.argv[1:])
        stream.write(f"llcps{(' ' + words) if words else ''}: starting")
        stream.flush()
    try:
        from llcps.cli.main import main as run
    finally:
        if early:
            stream.write(_CLEAR_LINE)
            stream.flush()
    run()


if __name__ == "__main__":
    main()
