"""Jobs: one plain function per command, the work a CLI command or the Python API asks for.

Each job takes keyword-only plain arguments and returns a frozen result; the CLI only
parses options and formats that result, and :mod:`llcps.api` calls the same function, so
a command and its API call can never compose the work differently.
"""
