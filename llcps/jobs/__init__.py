"""Jobs: one plain function per command, the work a CLI command or the Python API asks for.

Each job takes keyword-only plain arguments and returns a frozen result; the CLI only
parses options and formats that result, and :mod:`llcps.api` calls the same function, so
a command and its API call can never compose the work differently.

A job takes ``store=``: a SQLite path or an SQLAlchemy URL, which it opens and closes, or an
open :class:`~llcps.store.Store` (the API's), which it leaves open. A long job reports through
``progress(phase, done=0, total=None)``, the shape of the CLI's progress display. Jobs import
neither the CLI nor typer or rich, and load the simulator, torch or scikit-learn only inside
the job that needs them.

* :mod:`llcps.jobs.pretrain`: ``llcps pretrain``
* :mod:`llcps.jobs.db`: ``llcps db ...``
* :mod:`llcps.jobs.scenario`: ``llcps scenario ...``
* :mod:`llcps.jobs.inspect`: ``llcps inspect ...``
* :mod:`llcps.jobs.replay`: ``llcps replay``
* :mod:`llcps.jobs.cache`: ``llcps cache ...``
"""
