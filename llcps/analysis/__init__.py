"""Analysis: reading an experiment's results and the statistics over them; no running
and no rendering.

The results table is read back and checked from a CSV, a JSON file or the store; the
paper's Figure 2 is recomputed over many seeds with bootstrap intervals and paired
tests (Holm's correction over every p-value of a report), unsolved episodes are treated
as censored (survival), models are compared with the random order, and the paper's
published numbers sit in :mod:`llcps.analysis.paper` to compare with. Everything is
computed once per table by :func:`llcps.analysis.analyse.analyse`.
"""
