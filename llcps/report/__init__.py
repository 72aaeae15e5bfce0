"""Reports: the tables, plots and HTML page an experiment's analysis is shown in
(the paper's Figure 2 beside ours, survival curves, films of resolving trials)."""
