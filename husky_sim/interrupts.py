"""Ctrl-C and SIGTERM end a run promptly and visibly, never as a normal-looking result.

`install()` is the first thing the command line does. Until `begin_run()` (called once the run's
output folder is about to be written) there is nothing to keep, and libraries are being loaded
that swallow interrupts (numpy turns one into an ImportError, trimesh catches BaseException), so a
signal then ends the process at once: one line on stderr and exit 128 + signal number. From
`begin_run()` on, both signals record themselves and raise `RunInterrupted`, a BaseException like
KeyboardInterrupt, so no `except Exception` turns it into something else and the run can write
what it has. Libraries that catch BaseException (trimesh does at import) or catch the
interrupt inside a C extension can swallow the raise, or turn it into an error of their own (NumPy
converting a CasADi matrix raises SystemError), so the signal is also remembered: `check()` at
every control step raises it again, the episode and the command line take any error raised while
a signal is pending for the interrupt, and `pending()` tells the command line to exit
128 + signal number (130 for SIGINT, 143 for SIGTERM) whatever happened in between.
`deferred()` holds delivery while a file is being written so a row or a summary is never half
written.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_state = {"signum": None, "defer": 0, "running": False}


class RunInterrupted(BaseException):
    """A run ended by a signal; `exit_code` is the shell's 128 + signal number."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


def signum_of(exc: BaseException) -> int:
    """The signal behind an interrupt: RunInterrupted's own, SIGINT for a KeyboardInterrupt raised
    where our handler was not in place."""
    return exc.signum if isinstance(exc, RunInterrupted) else int(signal.SIGINT)


def _handle(signum: int, _frame: object) -> None:
    if not _state["running"]:  # start-up: nothing written yet, nothing to save
        code = 128 + signum
        name = signal.Signals(signum).name
        os.write(2, f"husky-sim: interrupted by {name} during start-up; exit {code}\n".encode())
        os._exit(code)
    first = _state["signum"] is None
    if first:
        _state["signum"] = signum
    if first and not _state["defer"]:
        raise RunInterrupted(signum)


def install() -> dict[int, object]:
    """Route SIGINT and SIGTERM to the handler above, in start-up mode, with nothing received yet;
    return the handlers it replaced, for `restore` (main thread only; elsewhere a no-op)."""
    _state.update(signum=None, defer=0, running=False)
    previous: dict[int, object] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in HANDLED_SIGNALS:
            previous[sig] = signal.signal(sig, _handle)
    return previous


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers `install` replaced (a command run in-process leaves no trace)."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)
    _state["running"] = False


def begin_run() -> None:
    """From now on a signal is raised as RunInterrupted so the run can keep what it has."""
    _state["running"] = True


def pending() -> int | None:
    """The signal received so far, if any."""
    return _state["signum"]


def check() -> None:
    """Raise RunInterrupted if a signal arrived (even one a library swallowed)."""
    if _state["signum"] is not None:
        raise RunInterrupted(_state["signum"])


def reset() -> None:
    """Forget a received signal (tests that interrupt several runs in one process)."""
    _state["signum"] = None


@contextmanager
def deferred() -> Iterator[None]:
    """Hold interrupt delivery while the body writes a file; the signal is kept, not lost."""
    _state["defer"] += 1
    try:
        yield
    finally:
        _state["defer"] -= 1
