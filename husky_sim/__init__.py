"""husky-nav-sim: the Husky A200 in PyBullet, scenarios, the validation suite and its tools.

Importing the package imports nothing heavy (PyBullet comes in through husky_sim.bullet where a
simulation module needs it), so the command line installs its signal handlers before any
library that could swallow an interrupt is loaded."""
