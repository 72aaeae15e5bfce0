"""Reading PDDL text with the `pddl` library, cheaply.

Building a `pddl` parser compiles its Lark grammar (~80 ms), parsing a small domain
takes ~5 ms, so parsers are kept and reused: one per thread (their transformers hold
state between calls), and a parser that raised is thrown away so that a half-finished
parse cannot leak into the next one. This module only reads text; what the text means
is up to its callers.
"""

from __future__ import annotations

import threading
from typing import Callable, TypeVar

from pddl.core import Domain, Problem
from pddl.parser.domain import DomainParser
from pddl.parser.problem import ProblemParser

T = TypeVar("T")
_local = threading.local()


def _parse(kind: str, factory: Callable[[], Callable[[str], T]], text: str) -> T:
    parser = getattr(_local, kind, None)
    if parser is None:
        parser = factory()
        setattr(_local, kind, parser)
    try:
        return parser(text)
    except BaseException:
        setattr(_local, kind, None)
        raise


def parse_domain_text(text: str) -> Domain:
    """A `pddl` library domain from PDDL text (raises the library's errors)."""
    return _parse("domain", DomainParser, text)


def parse_problem_text(text: str) -> Problem:
    """A `pddl` library problem from PDDL text (raises the library's errors)."""
    return _parse("problem", ProblemParser, text)
