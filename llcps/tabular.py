"""One spelling of values in text tables, for every CSV llcps writes (trial exports,
results, report tables): booleans ``true``/``false`` as in JSON, absent values empty."""

from __future__ import annotations

from typing import Any


def csv_value(value: Any) -> Any:
    """``value`` as a CSV field: booleans ``true``/``false``, None empty, anything else as is."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value
