"""The `llcps` command line (typer): one module per command group, each command parsing
its options, calling one job of :mod:`llcps.jobs` and formatting the result (tables,
``--json``, progress on stderr). Errors become one ``error:`` and one ``hint:`` line and
exit code 2, never a traceback. See docs/cli.md."""
