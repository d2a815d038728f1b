"""Signals during a solve: an interrupt must stop the program, never become a failed solve.

CasADi checks for Python signals while IPOPT iterates; a SIGINT handler that raises there is
caught inside CasADi, which then reports `NonIpopt_Exception_Thrown`, and a control loop would
take that for a solver failure and brake on. `deliver_after_solve` wraps one solver call: a
SIGINT or SIGTERM arriving during it aborts the solve (CasADi sees KeyboardInterrupt) and is then
delivered to the program's own handler once the solver has returned, outside CasADi, so the
program's handler decides what happens (Python's default raises KeyboardInterrupt). If that
handler returns normally, KeyboardInterrupt is raised anyway: the aborted solve has no answer.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: Signals whose Python handlers CasADi would otherwise run (and swallow) inside a solve.
WATCHED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class SolveInterrupted(KeyboardInterrupt):
    """A signal ended a solve and the program's handler did not raise."""


@contextmanager
def deliver_after_solve() -> Iterator[None]:
    """Run the body with SIGINT/SIGTERM recorded (and the solve aborted) instead of handled;
    deliver a recorded signal to the original handler afterwards. Main thread only (the only
    thread Python runs signal handlers in); elsewhere the body runs unchanged."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def record(signum: int, _frame: object) -> None:
        received.append(signum)
        raise KeyboardInterrupt  # CasADi aborts the solve at its next signal check

    originals = {}
    for sig in WATCHED_SIGNALS:
        handler = signal.getsignal(sig)
        if callable(handler):  # SIG_DFL / SIG_IGN: the OS acts, CasADi never sees the signal
            originals[sig] = handler
            signal.signal(sig, record)
    try:
        yield
    except KeyboardInterrupt:
        if not received:
            raise
    finally:
        for sig, handler in originals.items():
            signal.signal(sig, handler)
    if received:
        signum = received[0]
        originals[signum](signum, None)
        raise SolveInterrupted(f"solve interrupted by {signal.Signals(signum).name}")
