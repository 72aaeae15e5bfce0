"""Analysis: reading an experiment's results and the statistics over them (paired
tests with Holm's correction, censoring-aware survival, the paper's published figures
to compare with); no running and no rendering."""
