"""Experiments: running the paper's evaluation grid over many seeds.

The paper (Gizzi et al., "Toward Life-Long Creative Problem Solving") evaluates each
world model x measure by solving scenario1 -> scenario2 -> scenario3 with model updates
and without ("reset"), four runs a cell, for 200 and for 4 pretraining points (its
Figure 2). This package runs that grid, and wider ones, over as many seeds as asked:
the design (cells, sequences, branch names), the presets, the tasks a run is made of,
the executors that run them (a local process pool or Ray), the worker, the scheduler
that imports each task's results into the one store, and the result rows a run's
episodes become. Reading the results and their statistics is :mod:`llcps.analysis`;
showing them is :mod:`llcps.report`; nothing here imports either.
"""
