"""`husky-sim suite`: a scenario x controller x horizon x gamma matrix in parallel."""

from __future__ import annotations

import argparse
import sys

from husky_sim import interrupts
from husky_sim.cli.common import (
    UsageError,
    add_backend_args,
    add_solver_arg,
    controller_choices,
    horizon_arg,
    jobs_arg,
    path_arg,
    seed_arg,
    unit_float_arg,
    warn_solve_budget,
)


def cmd_suite(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.runs.run_folder import prepare_out_dir
    from husky_sim.runs.scenario import load_scenario, shipped_scenarios
    from husky_sim.study.suite import markdown_table, matrix, run_suite, write_figures

    if args.scheduler is not None and args.backend != "dask":
        raise UsageError("--scheduler: needs --backend dask")
    names = args.scenarios or [p.stem for p in shipped_scenarios()]
    for name in names:  # bad input fails here, in one line, before any worker starts
        sc = load_scenario(name)
        for horizon in args.horizons or [None]:
            for gamma in args.gammas or [None]:
                sc.with_overrides(horizon, gamma, args.seed, args.solver)
    cells = matrix(
        names, args.controllers, args.horizons or [None], args.gammas or [None], args.seed, args.solver
    )
    interrupts.begin_run()
    out = prepare_out_dir(Path(args.out))
    try:
        rows = run_suite(
            cells,
            jobs=args.jobs,
            out_dir=out,
            progress=not args.quiet,
            backend=args.backend,
            scheduler=args.scheduler,
        )
    except interrupts.RunInterrupted:
        print(
            f"husky-sim: suite interrupted: no results.csv written; runs so far in {out / 'runs'}",
            file=sys.stderr,
        )
        raise
    for row in rows:
        warn_solve_budget(row, f"{row.get('run_dir') or row['scenario']}: ")
    figures = write_figures(rows, out, per_run=args.plots, jobs=args.jobs)
    print(markdown_table(rows), end="")
    print(f"{len(figures)} figures (PNG and SVG) -> {out / 'plots'}")
    errors = [r for r in rows if r["outcome"] == "error"]
    for r in errors:
        print(f"error in {r['run_dir']}: {r['error']}", file=sys.stderr)
    print(f"{len(rows)} runs -> {out / 'results.csv'}, {out / 'results.md'}")
    return 1 if errors else 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `suite`."""
    from husky_sim.runs.run_folder import SUITE_DIR

    suite = sub.add_parser("suite", help="run a scenario x controller x horizon x gamma matrix in parallel")
    suite.add_argument("--scenarios", nargs="+", default=None, help="names or paths (default: all shipped)")
    suite.add_argument(
        "--controllers",
        nargs="+",
        choices=controller_choices(),
        default=list(controller_choices(paper_only=True, with_baseline=False)),
    )
    suite.add_argument("--horizons", nargs="+", type=horizon_arg, default=None, help="default: file's N")
    suite.add_argument("--gammas", nargs="+", type=unit_float_arg, default=None, help="default: file's gamma")
    suite.add_argument("--seed", type=seed_arg, default=None, help="seed (default: the file's)")
    suite.add_argument("--jobs", type=jobs_arg, default=2, help="worker processes (default 2)")
    add_solver_arg(suite)
    add_backend_args(suite, "runs")
    suite.add_argument(
        "--out", type=path_arg, default=str(SUITE_DIR), help=f"output directory (default {SUITE_DIR})"
    )
    suite.add_argument("--quiet", action="store_true", help="no progress bar")
    suite.add_argument("--plots", action="store_true", help="also every run's own figures")
    suite.set_defaults(func=cmd_suite)
