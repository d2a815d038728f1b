"""Runs: the scenario schema and its resolution into run-time configuration, one scenario run
with its run folder (summary, log, trace, MCAP), the paper's problems as data, and the parallel
map that suite and sweep share."""
