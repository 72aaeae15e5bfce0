"""llcps: life-long creative problem solving with world models.

A PyBullet robot with a symbolic PDDL knowledge base runs plans; a novelty makes a
plan fail; the robot explores alternative action parameterizations, guided by a
world model trained on every trial it has ever executed, until it resolves the
novelty and learns a new operator.
"""

from llcps._version import __version__

__all__ = ["__version__", "open"]


def open(url_or_path="llcps.db", *, create=False):  # noqa: A001 - the API's entry point
    """Open an experience store for analysis: a :class:`llcps.api.Workbench`.

    ``llcps.open("llcps.db").trials()`` is a pandas DataFrame of every trial the
    current branch sees. pandas loads on the first call, not with ``import llcps``.
    """
    from llcps.api import Workbench

    return Workbench.open(url_or_path, create=create)
