"""``llcps cache``: the store's physics cache — how big it is, its bound, and pruning it."""

from __future__ import annotations

import re
from typing import Annotated, Optional

import typer

from llcps.cli._common import JsonFlag, db_location, human_bytes, message, new_app, notice, print_json, print_table
from llcps.cli._conventions import examples
from llcps.errors import LlcpsError
from llcps.jobs import cache as jobs

app = new_app(
    "The physics cache: simulated trials kept in the store, answered again instead of simulated "
    "(see `llcps experiment run --no-cache`).",
    epilog=examples("llcps cache status", "llcps cache limit 4GB && llcps cache prune"),
)

_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "KIB": 1 << 10, "MIB": 1 << 20, "GIB": 1 << 30}
_SIZE = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([A-Za-z]*)\s*$")


def parse_size(text: str) -> int:
    """Bytes in a size such as ``500MB``, ``2GiB`` or ``0``."""
    match = _SIZE.match(text)
    unit = match.group(2).upper() if match else ""
    if match is None or unit not in _UNITS:
        raise LlcpsError(f"not a size: {text!r}", hint="write a number of bytes with an optional unit: 500MB, 2GB, 1GiB, 0")
    return int(float(match.group(1)) * _UNITS[unit])


@app.command("status", epilog=examples("llcps cache status", "llcps cache status --json"))
def status_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """Entries, bytes and the size bound of the physics cache."""
    status = jobs.cache_status(store=db_location(ctx))
    if as_json:
        print_json(status.as_json())
        return
    print_table(
        None,
        ("", ""),
        [
            ("entries", status.entries),
            ("sealed", f"{status.sealed} (restored without the state checks by the user who sealed them)"),
            ("size", f"{human_bytes(status.bytes)} of {human_bytes(status.max_bytes)} allowed"),
            ("hits recorded", status.hits),
            ("last used", f"{status.oldest_use or '-'} .. {status.newest_use or '-'}"),
        ],
        show_header=False,
    )


@app.command(
    "prune",
    epilog=examples("llcps cache prune --dry-run", "llcps cache prune --to 500MB", "llcps cache prune --to 0  # empty it"),
)
def prune_cli(
    ctx: typer.Context,
    to: Annotated[
        Optional[str],
        typer.Option("--to", metavar="SIZE", help="Keep at most this much (500MB, 2GB; 0 empties the cache). Default: the store's bound (`llcps cache limit`).", show_default=False),
    ] = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Only report what would be removed.")] = False,
    as_json: JsonFlag = False,
) -> None:
    """Remove the least recently used entries until the cache fits its bound.

    An experiment run does this when it ends; no branch loses anything, later runs
    simulate the removed trials again.
    """
    limit = parse_size(to) if to is not None else None
    result = jobs.prune_cache(store=db_location(ctx), limit=limit, dry_run=dry_run)
    if as_json:
        print_json(result.as_json())
    verb = "would remove" if dry_run else "removed"
    (notice if dry_run else message)(f"{verb} {result.removed} entries ({human_bytes(result.removed_bytes)}); {result.kept} kept ({human_bytes(result.kept_bytes)})")


@app.command("limit", epilog=examples("llcps cache limit 4GB && llcps cache prune"))
def limit_cli(
    ctx: typer.Context,
    size: Annotated[str, typer.Argument(metavar="SIZE", help="The bound, e.g. 500MB or 4GB.", show_default=False)],
    as_json: JsonFlag = False,
) -> None:
    """Set the size bound the cache is pruned to (stored in the store; default 2 GiB)."""
    limit = parse_size(size)
    status = jobs.limit_cache(store=db_location(ctx), max_bytes=limit)
    if as_json:
        print_json(status.as_json())
    message(f"physics cache bound: {human_bytes(limit)} (holds {human_bytes(status.bytes)}; `llcps cache prune` trims it now)")
