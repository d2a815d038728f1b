"""`husky-sim plot`: figures of runs, or tuning maps of a suite."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import UsageError, path_arg


def cmd_plot(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.viz.comparison_figures import plot_runs
    from husky_sim.viz.run_figures import RUN_FIGURES
    from husky_sim.viz.tuning_maps import plot_tuning_maps

    if not args.run_dirs and not args.results:
        raise UsageError("plot: give one or more run directories, or --results results.csv")
    if args.scenario and not args.results:
        raise UsageError("plot: --scenario only applies to --results")
    try:
        if args.run_dirs:
            plotted = plot_runs(args.run_dirs, args.out)
            for run_dir, target in plotted.runs.items():
                print(f"{run_dir}: {len(RUN_FIGURES)} figures (PNG and SVG) -> {target}")
            if plotted.comparison is not None:
                print(f"comparison of {len(args.run_dirs)} runs -> {plotted.comparison[0]}")
        if args.results:
            out = Path(args.out) if args.out else Path(args.results).parent / "plots"
            maps = plot_tuning_maps(args.results, out, args.scenario)
            print(f"{len(maps)} tuning maps (PNG and SVG) -> {out}")
    except OSError as exc:
        raise UsageError(f"plot: cannot write figures ({exc})") from None
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `plot`."""
    plot = sub.add_parser("plot", help="figures of runs (PNG and SVG), or tuning maps of a suite")
    plot.add_argument("run_dirs", nargs="*", metavar="RUN_DIR", help="run directories (husky-sim run --out)")
    plot.add_argument("--results", default=None, help="a suite's results.csv: gamma x N tuning maps")
    plot.add_argument("--scenario", default=None, help="with --results: only this scenario's maps")
    plot.add_argument(
        "--out",
        type=path_arg,
        default=None,
        help="output directory (default RUN_DIR/plots, or beside results.csv)",
    )
    plot.set_defaults(func=cmd_plot)
