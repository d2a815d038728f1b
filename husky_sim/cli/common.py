"""What every command shares: the controller and solver names, argument types that give a one-line
error naming the allowed range, the usage error, and the warnings printed on stderr."""

from __future__ import annotations

import argparse
import math
import sys


def controller_choices(paper_only: bool = False, with_baseline: bool = True) -> tuple[str, ...]:
    """The controllers a command may choose: every registered one (controllers.registry), or the
    paper's. Read when the parser is built, after the signal handlers are in place (the registry
    imports the controllers, and with them CasADi)."""
    from controllers import registry

    return registry.paper_names(with_baseline) if paper_only else registry.names()


def default_controller(on_robot: bool = False) -> str:
    """The controller a command runs unless told (controllers.registry's defaults)."""
    from controllers import registry

    return registry.DEFAULT_ON_ROBOT if on_robot else registry.DEFAULT


#: The NLP solver backends (controllers.config.SOLVER_BACKENDS, likewise kept equal by a test).
SOLVER_CHOICES = ("fatrop", "ipopt", "opti")
#: Those a run can use for every controller (a scenario's controller.solver, likewise kept equal by
#: a test): `opti` is the paper controllers' own baseline, which only `bench` builds.
RUN_SOLVER_CHOICES = ("fatrop", "ipopt")
#: The longest horizon N a command takes (husky_sim.runs.scenario.MAX_HORIZON, likewise).
MAX_HORIZON = 50
#: The most payload (kg) a command reads (husky_sim.runs.scenario.MAX_PAYLOAD_KG, likewise); the
#: check then bounds it by the scenario robot's own maximum.
MAX_PAYLOAD_KG = 1000.0


class UsageError(Exception):
    """A user mistake: printed as one line, exit code 2."""


class OneLineErrorParser(argparse.ArgumentParser):
    """argparse, but a usage mistake prints one line (no usage block) and exits 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def number_in(kind: type[int] | type[float], low: float, high: float):
    """An argparse type: an integer (kind int) or a finite number (kind float) in [low, high],
    else a one-line error naming the range."""
    word = "an integer" if kind is int else "a number"
    bounds = f"[{low}, {high}]" if kind is int else f"[{low:g}, {high:g}]"

    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {word} in {bounds}, got {text[:40]!r}") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f"expected {word} in {bounds}, got {value:g}")
        return value

    return parse


def path_arg(text: str) -> str:
    """An argparse type: a non-empty path (an empty --out would silently mean the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    return text


#: Port of Foxglove's WebSocket server for --live (Foxglove's own default).
LIVE_PORT = 8765

#: Bounds of the command line's counts: what a 2-core machine (or a cluster) can reasonably run.
MAX_JOBS = 256
MAX_SAMPLES = 100_000
horizon_arg = number_in(int, 1, MAX_HORIZON)
HORIZON_HELP = f"prediction steps N in [1, {MAX_HORIZON}]"
seed_arg = number_in(int, 0, 2**32 - 1)
jobs_arg = number_in(int, 1, MAX_JOBS)
count_arg = number_in(int, 1, MAX_SAMPLES)
unit_float_arg = number_in(float, 0.0, 1.0)
payload_arg = number_in(float, 0.0, MAX_PAYLOAD_KG)


#: Where a suite's runs or a check's samples run (husky_sim.runs.parallel.BACKENDS, kept equal by
#: a test).
PARALLEL_BACKENDS = ("local", "dask")


def add_solver_arg(parser: argparse.ArgumentParser) -> None:
    """--solver: the NLP backend of every NMPC the command runs (default: the scenario file's,
    else the structured FATROP with its IPOPT fallback)."""
    parser.add_argument(
        "--solver",
        choices=RUN_SOLVER_CHOICES,
        default=None,
        help="NLP backend (default: the scenario's, else fatrop)",
    )


def add_backend_args(parser: argparse.ArgumentParser, what: str) -> None:
    """--backend and --scheduler: local worker processes or a Dask cluster (runs.parallel)."""
    parser.add_argument("--backend", choices=PARALLEL_BACKENDS, default="local", help=f"where {what} run")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address (default: a LocalCluster)")


def warn(message: str) -> None:
    print(f"husky-sim: warning: {message}", file=sys.stderr)


def warn_solve_budget(summary: dict[str, object], label: str = "") -> None:
    """Say on stderr when solves took longer than tau (the summary says so too)."""
    over = summary.get("solves_over_budget") or 0
    if over:
        warn(
            f"{label}{over} of {summary['steps']} solves took longer than tau = "
            f"{summary['solve_budget_ms']:g} ms (median {summary['solve_ms_median']:.1f} ms, max "
            f"{summary['solve_ms_max']:.1f} ms): on a robot those commands would arrive late"
        )


def add_live_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--live",
        type=number_in(int, 1, 65535),
        nargs="?",
        const=LIVE_PORT,
        default=None,
        metavar="PORT",
        help=f"also stream the run to Foxglove's WebSocket server on 127.0.0.1:PORT (default {LIVE_PORT})",
    )


def announce_live(args: argparse.Namespace) -> None:
    if args.live is not None:
        print(f"streaming to Foxglove: open ws://127.0.0.1:{args.live} in Foxglove", flush=True)
