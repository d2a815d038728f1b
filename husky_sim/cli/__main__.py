"""`python -m husky_sim.cli`: the `husky-sim` program."""

from husky_sim.cli import entry

entry()
