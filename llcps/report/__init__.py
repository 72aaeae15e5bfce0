"""Reports: how an experiment's analysis is shown, as files in one directory.

Our Figure 2 beside the paper's (tables and a heatmap), the other comparisons' tables,
survival curves and distribution plots, a plain-words summary, ``report.md`` and the
self-contained ``report.html`` with a film of a resolving trial per scenario. Every
number comes from :mod:`llcps.analysis`; :func:`llcps.report.build.build_report` writes
them all.
"""
