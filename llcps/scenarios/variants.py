"""Scene variants: a concrete scene drawn from a scenario file's ranges with a variant seed.

Variant 0 is the canonical scene: every range gives its middle and every list of
colours its first. Variant N > 0 draws each varying field from a hash of
``(N, attempt, field)``, where the field is named by its entity (or fixture) and key,
not by its place in the file: both conditions of a variant draw the same value for a
field they share, a copy of a file draws what the original draws, and widening one
range leaves every other draw of the variant as it was. Values are rounded to
:data:`DIGITS` decimals, so a variant can be written back to a file exactly.

A draw whose layout fails the checks of :mod:`llcps.scenarios.layout` in either
condition (an overlap, a floating body, an entity out of declared reach) is redrawn
with the next attempt, deterministically, up to :data:`MAX_ATTEMPTS`; a range that
never gives a valid layout is refused with an error. Variant 0 is never redrawn: a
canonical scene that fails the checks is an error in the file.
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING, Any, Callable

from llcps.errors import LlcpsError

if TYPE_CHECKING:
    from llcps.scenarios.file_format import Scalar

#: Decimals of every drawn value (0.1 mm, 0.1 g, 0.0001 rad).
DIGITS = 4
#: Draws of one variant's layout before its ranges are refused.
MAX_ATTEMPTS = 100
#: Largest variant number: a variant is a seed, and seeds are 32 bits everywhere.
MAX_VARIANT = 2**32 - 1


def unit(variant: int, attempt: int, key: str) -> float:
    """A number in [0, 1) fixed by (variant, attempt, key): the same on every machine."""
    digest = hashlib.sha256(f"{variant}:{attempt}:{key}".encode()).digest()
    return (int.from_bytes(digest[:8], "big") >> 11) / float(1 << 53)


def is_range(value: Any) -> bool:
    """Whether a field value is a range or a list of choices (it varies between variants)."""
    return isinstance(value, tuple)


def number(value: Scalar, draw: Callable[[], float] | None) -> float:
    """A number field's value: itself, or from its range (the middle when ``draw`` is None)."""
    if not isinstance(value, tuple):
        return float(value)
    low, high = value
    u = 0.5 if draw is None else draw()
    return round(low + u * (high - low), DIGITS)


def choice(value: str | tuple[str, ...], draw: Callable[[], float] | None) -> str:
    """A choice field's value: itself, or one of its options (the first when ``draw`` is None)."""
    if isinstance(value, str):
        return value
    return value[0] if draw is None else value[min(int(draw() * len(value)), len(value) - 1)]


class Draws:
    """The draws of one (variant, attempt): ``draw(key)`` gives the unit number of a field."""

    def __init__(self, variant: int, attempt: int) -> None:
        self.variant = variant
        self.attempt = attempt

    def number(self, value: Scalar, key: str) -> float:
        return number(value, None if self.variant == 0 else (lambda: unit(self.variant, self.attempt, key)))

    def choice(self, value: str | tuple[str, ...], key: str) -> str:
        return choice(value, None if self.variant == 0 else (lambda: unit(self.variant, self.attempt, key)))


def check_variant(variant: object) -> int:
    """A variant number, or an error saying what one is."""
    if isinstance(variant, bool) or not isinstance(variant, int) or not 0 <= variant <= MAX_VARIANT:
        raise LlcpsError(
            f"a variant is a number from 0 to {MAX_VARIANT}, not {variant!r}", hint="variant 0 is the canonical scene"
        )
    return variant


def parse_range(text: str) -> range:
    """A range of variants from the command line: ``A:B`` is A..B-1, ``N`` is N alone."""
    parts = text.strip().split(":")
    try:
        bounds = [int(p) for p in parts]
    except ValueError:
        bounds = []
    if len(parts) == 1 and len(bounds) == 1 and 0 <= bounds[0] <= MAX_VARIANT:
        return range(bounds[0], bounds[0] + 1)
    if len(parts) == 2 and len(bounds) == 2 and 0 <= bounds[0] < bounds[1] <= MAX_VARIANT + 1:
        return range(bounds[0], bounds[1])
    raise LlcpsError(
        f"not a range of variants: {text!r}",
        hint=f"write A:B for variants A..B-1 (0 <= A < B <= {MAX_VARIANT + 1}), e.g. 0:20, or one variant N",
    )


def range_text(variants: range) -> str:
    """``range(0, 10)`` -> ``0:10`` (the form :func:`parse_range` reads)."""
    return f"{variants.start}:{variants.stop}"


__all__ = [
    "DIGITS",
    "MAX_ATTEMPTS",
    "MAX_VARIANT",
    "Draws",
    "check_variant",
    "choice",
    "is_range",
    "number",
    "parse_range",
    "range_text",
    "unit",
]
