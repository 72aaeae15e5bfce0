"""One project error, carrying a hint at the fix, so the CLI can print a single
clear line (and exit non-zero) instead of a traceback."""

from __future__ import annotations


class LlcpsError(Exception):
    """A failure the user can act on.

    Args:
        message: what went wrong, in one sentence.
        hint: what to do about it (a command to run, a valid value), if known.
        exit_code: the CLI exit code; 2 for bad input, 1 for a run that did not succeed.
    """

    exit_code: int = 2

    def __init__(self, message: str, *, hint: str | None = None, exit_code: int | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint
        if exit_code is not None:
            self.exit_code = exit_code

    def __str__(self) -> str:
        return self.message if not self.hint else f"{self.message} ({self.hint})"


def _plural(noun: str) -> str:
    return noun + ("es" if noun.endswith(("s", "sh", "ch", "x")) else "s")


class StoreError(LlcpsError):
    """The experience store cannot be opened, read or written as asked."""


class UnknownNameError(LlcpsError):
    """A scenario, world model, measure or branch name that does not exist."""

    def __init__(self, kind: str, name: str, known: list[str] | tuple[str, ...]) -> None:
        super().__init__(
            f"unknown {kind} {name!r}",
            hint=f"known {_plural(kind)}: {', '.join(known) if known else '(none)'}",
        )
