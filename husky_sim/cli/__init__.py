"""`husky-sim` command line. User mistakes give one line on stderr and exit code 2; Ctrl-C and
SIGTERM exit 130 and 143 (husky_sim.interrupts), with what was run so far kept and marked
`interrupted`.

Heavy modules (CasADi, PyBullet's worlds, the scenario schema) are imported after the signal
handlers are installed, so an interrupt during start-up is honoured too. Each command is one module
here (its parser and its handler); this one builds the parser and runs a command.
"""

from __future__ import annotations

import argparse
import atexit
import os
import sys
import warnings
from collections.abc import Sequence

from husky_sim import interrupts
from husky_sim.cli import (
    bench,
    calibrate,
    campaign,
    check,
    families,
    identify,
    paper,
    plot,
    render,
    replay,
    ros2,
    run,
    scenarios,
    settings,
    suite,
)
from husky_sim.cli.common import SOLVER_CHOICES, OneLineErrorParser, UsageError, warn
from husky_sim.extras import MissingExtra

__all__ = ["SOLVER_CHOICES", "UsageError", "build_parser", "entry", "main"]

#: The commands in the order `husky-sim --help` lists them.
COMMANDS = (
    scenarios,
    settings,
    families,
    run,
    ros2,
    render,
    suite,
    campaign,
    paper,
    bench,
    check,
    plot,
    identify,
    replay,
    calibrate,
)


def build_parser() -> argparse.ArgumentParser:
    """The `husky-sim` parser: one sub-command per module of COMMANDS."""
    parser = OneLineErrorParser(prog="husky-sim", description="Husky A200 NMPC-CLF/CBF validation suite")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parsers(sub)
    return parser


def _interrupted(signum: int) -> int:
    code = interrupts.RunInterrupted(signum).exit_code
    print(f"husky-sim: {interrupts.RunInterrupted(signum)}; exit {code}", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; return its exit code. The signal handlers live only as long as the command
    (a caller that runs it in-process keeps its own)."""
    previous = interrupts.install()  # first: an interrupt during start-up is honoured too
    try:
        with warnings.catch_warnings():  # a library's UserWarning (no run.mcap) as one line
            warnings.showwarning = _show_warning
            # a library's deprecation is for its developers (Python hides them by default outside
            # __main__), whatever filters the caller runs the command under, unless -W asks
            if not sys.warnoptions:
                warnings.filterwarnings("ignore", category=DeprecationWarning)
                warnings.filterwarnings("ignore", category=PendingDeprecationWarning)
            return _run_command(argv)
    finally:
        interrupts.restore(previous)


def _show_warning(message: Warning | str, *_: object, **__: object) -> None:
    warn(str(message))


def _run_command(argv: Sequence[str] | None) -> int:
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # a usage mistake (one line, exit 2) or --help (exit 0)
            return int(exc.code or 0)
        interrupts.check()
        code = args.func(args)
    except interrupts.RunInterrupted as exc:
        return _interrupted(exc.signum)
    except KeyboardInterrupt:  # raised where our handler was not in place
        return _interrupted(interrupts.pending() or 2)
    except Exception as exc:
        signum = interrupts.pending()
        if signum is not None:  # a signal raised inside a C extension came back as its error
            return _interrupted(signum)
        return _error(exc)
    signum = interrupts.pending()  # a signal a library swallowed still ends the command as one
    return _interrupted(signum) if signum is not None else code


def _error(exc: Exception) -> int:
    """One line on stderr and the exit code for an error that ended a command; re-raised if it is
    neither the user's nor the machine's (a bug: its traceback is wanted)."""
    if isinstance(exc, UsageError | ValueError):  # ConfigError and ScenarioError are ValueErrors
        print(f"husky-sim: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    if isinstance(exc, MissingExtra):  # the install, not the user: which extra to add
        print(f"husky-sim: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    if isinstance(exc, BrokenPipeError):  # `husky-sim scenarios | head`: the reader left
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    if isinstance(exc, OSError):  # the machine, not the user: a full disk, a vanished directory
        print(f"husky-sim: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    raise exc


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 500 else text[:497] + "..."


def entry() -> None:
    """The `husky-sim` program: `main`, then exit. An interrupted command leaves at once, with its
    output flushed and its files already closed: the interpreter's teardown of CasADi, PyBullet and
    SciPy costs 0.4 s of CPU here and over a second on a loaded machine, which would break the
    promise that a signal ends a run within a second."""
    code = main()
    if code in {128 + int(sig) for sig in interrupts.HANDLED_SIGNALS}:
        atexit._run_exitfuncs()  # multiprocessing's own clean-up (its semaphores), then no teardown
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
