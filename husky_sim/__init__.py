"""husky-nav-sim: the Husky A200 in PyBullet, scenarios, the validation suite and its tools.

Importing the package registers the gymnasium environment "HuskyNav-v0"
(husky_sim.runs.environment) where gymnasium is installed (the `gym` extra), and imports nothing
else heavy (PyBullet comes in through
husky_sim.sim.bullet where a simulation module needs it). Gymnasium (and NumPy under it) is
imported with SIGINT and SIGTERM held back: this runs before the command line can install its
signal handlers, and NumPy turns an interrupt during its import into an ImportError; a held
signal is delivered right after, with Python's default meaning."""

from __future__ import annotations

import signal
import threading

#: The gymnasium id of the simulated Husky (husky_sim.sim.environment.HuskyNavEnv).
ENV_ID = "HuskyNav-v0"


def _register_environments() -> None:
    held = (signal.SIGINT, signal.SIGTERM)
    can_hold = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held) if can_hold else None
    try:
        try:
            import gymnasium
        except ImportError:  # the core install: no environment to register
            return
        if ENV_ID not in gymnasium.registry:
            gymnasium.register(ENV_ID, entry_point="husky_sim.runs.environment:make_husky_nav")
    finally:
        if previous is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)


_register_environments()
