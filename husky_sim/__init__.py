"""husky-nav-sim: the Husky A200 in PyBullet, scenarios, the validation suite and its tools."""

import os
import sys


def _import_pybullet_quietly() -> None:
    """Import PyBullet with its C-level "pybullet build time" banner (printed to the process's
    stderr on import) discarded, so a command's error stays one line. Errors still propagate."""
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
