"""PyBullet, imported once with its C-level "pybullet build time" banner discarded (it is printed
to the process's stderr on import), so a command's error stays one line. Simulation modules take
`pybullet` from here; errors still propagate."""

import os
import sys


def _import_pybullet_quietly() -> None:
    if "pybullet" in sys.modules:
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr file descriptor (embedded use): import as is
        import pybullet  # noqa: F401

        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(devnull)
        os.close(saved)


_import_pybullet_quietly()

import pybullet  # noqa: E402  (already imported above, quietly)

__all__ = ["pybullet"]
