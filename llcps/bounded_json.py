"""JSON from a database or a file, decoded within bounds: its size and its nesting.

``json.loads`` decodes any size and recurses once per nesting level, so a value of a
few kilobytes can raise ``RecursionError`` deep inside a caller that expected a
``ValueError``. :func:`loads` is the one decoder for JSON llcps did not just write
itself: a value too large or nested too deeply is a ``ValueError`` naming the limit.
"""

from __future__ import annotations

import json
from typing import Any

#: Largest JSON text decoded (characters or bytes).
MAX_JSON_BYTES = 4 * 2**20

#: Deepest nesting of arrays and objects decoded (llcps writes at most about 8).
MAX_JSON_DEPTH = 64


class JsonLimitError(ValueError):
    """A JSON value beyond :data:`MAX_JSON_BYTES` or :data:`MAX_JSON_DEPTH`."""


def loads(text: str | bytes | bytearray, *, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Decode ``text`` as JSON, refusing values larger or deeper than the bounds.

    Raises:
        JsonLimitError: the text is longer than ``max_bytes`` or nests deeper than ``max_depth``.
        ValueError: the text is not JSON (``json.JSONDecodeError``, ``UnicodeDecodeError``).
    """
    if len(text) > max_bytes:
        raise JsonLimitError(f"a JSON value of {len(text):,} bytes, more than the {max_bytes:,} allowed")
    try:
        value = json.loads(text)
    except RecursionError:
        raise JsonLimitError(f"a JSON value nested deeper than {max_depth} levels") from None
    if depth(value, limit=max_depth) > max_depth:
        raise JsonLimitError(f"a JSON value nested deeper than {max_depth} levels")
    return value


def depth(value: Any, *, limit: int = MAX_JSON_DEPTH) -> int:
    """How deeply arrays and objects nest in a decoded value (a scalar: 0), without
    recursion; stops counting just past ``limit``."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        node, level = stack.pop()
        if isinstance(node, (list, dict)):
            level += 1
            deepest = max(deepest, level)
            if deepest > limit:
                return deepest
            stack.extend((child, level) for child in (node.values() if isinstance(node, dict) else node))
    return deepest
