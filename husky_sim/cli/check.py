"""`husky-sim check`: audit + robustness sweep -> PASS / FAIL before a Husky trial."""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import TYPE_CHECKING

from husky_sim import interrupts
from husky_sim.cli.common import (
    add_backend_args,
    add_solver_arg,
    controller_choices,
    count_arg,
    default_controller,
    horizon_arg,
    jobs_arg,
    number_in,
    path_arg,
    payload_arg,
    seed_arg,
    unit_float_arg,
)

#: Shortest and longest lidar range (m) `--sensing-range-m` takes (the longest is
#: husky_sim.runs.scenario.MAX_SENSING_RANGE_M, kept equal by a test: the CLI does not import the
#: schema until it runs).
MIN_SENSING_RANGE_M = 0.1
MAX_SENSING_RANGE_M = 1000.0
sensing_range_arg = number_in(float, MIN_SENSING_RANGE_M, MAX_SENSING_RANGE_M)

if TYPE_CHECKING:
    from husky_sim.realcheck.check import CheckOptions
    from husky_sim.runs.scenario import Scenario


def _options(args: argparse.Namespace, seed: int | None) -> CheckOptions:
    """The check's options from the command line; integers are range-checked by CheckOptions, so
    "--samples 0" is one line, exit 2."""
    from husky_sim.realcheck.check import CheckOptions
    from husky_sim.realcheck.sweep import PerturbationRanges

    ranges = PerturbationRanges()
    if args.payload_kg is not None:
        ranges = replace(ranges, payload_kg=tuple(args.payload_kg))
    if args.sensing_range_m is not None:
        low, high = args.sensing_range_m
        if low > high:
            raise ValueError(f"--sensing-range-m: LOW ({low:g}) must not exceed HIGH ({high:g})")
        ranges = replace(ranges, sensing_range_m=(low, high))
    if args.occlusion:
        ranges = replace(ranges, occlusion=(1, 1))
    return CheckOptions(
        controller=args.controller,
        horizon=args.horizon,
        samples=args.samples,
        seed=seed,
        jobs=args.jobs,
        backend=args.backend,
        scheduler=args.scheduler,
        timing_solves=args.timing_solves,
        min_pass_rate=args.min_pass_rate,
        ranges=ranges,
    )


def _scenario(name: str, args: argparse.Namespace, options: CheckOptions) -> Scenario:
    """The scenario on the chosen solver, its horizon and payload range checked before any work."""
    from husky_sim.runs.scenario import load_scenario

    sc = load_scenario(name).with_overrides(solver=args.solver)
    sc.with_overrides(horizon=args.horizon)  # range-checked here
    options.ranges.for_robot(sc.robot.description())  # a payload the robot cannot carry: refused here
    return sc


def cmd_check(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.realcheck.check import run_check
    from husky_sim.runs.run_folder import default_check_dir, prepare_out_dir

    options = _options(args, args.seed)
    sc = _scenario(args.scenario, args, options)
    horizon = sc.with_overrides(horizon=args.horizon).controller.horizon
    seed = sc.seed if args.seed is None else args.seed
    interrupts.begin_run()  # workers are stopped, not orphaned, on a signal
    out = prepare_out_dir(
        Path(args.out or default_check_dir(sc.name, args.controller, horizon, args.samples, seed))
    )
    report = run_check(sc, options, out, log=print)
    s = report.stats
    print(f"sweep: {s['passed']}/{s['samples']} passed ({s['pass_rate']:.0%}), outcomes {s['outcomes']}")
    print(f"{report.verdict}: {report.reason}")
    print(f"-> {out / 'check.md'}, {out / 'check.json'}")
    return 0 if report.verdict == "PASS" else 1


def cmd_check_table(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.realcheck.check_table import run_check_table
    from husky_sim.runs.run_folder import RESULTS_DIR, prepare_out_dir
    from husky_sim.runs.scenario import shipped_scenarios

    options = _options(args, None)
    names = args.scenarios or [path.stem for path in shipped_scenarios()]
    scenarios = [_scenario(name, args, options) for name in names]
    interrupts.begin_run()
    out = prepare_out_dir(Path(args.out or RESULTS_DIR / f"check_table__{args.controller}"))
    cells = run_check_table(scenarios, args.seeds, options, out, log=print)
    passed = sum(c.verdict == "PASS" for c in cells)
    print(f"{passed} of {len(cells)} checks PASS -> {out / 'check_table.md'}, {out / 'check_table.json'}")
    return 0 if passed == len(cells) else 1


def _add_check_options(parser: argparse.ArgumentParser) -> None:
    """What `check` and `check-table` share: the controller, N, samples, solver, workers, the pass
    rate needed, the payload range and the lidar's visibility model."""
    parser.add_argument("--controller", choices=controller_choices(), default=default_controller())
    parser.add_argument(
        "--horizon", type=horizon_arg, default=None, help="prediction steps N (default: the file's)"
    )
    parser.add_argument("--samples", type=count_arg, default=32, help="perturbed runs K >= 1 (default 32)")
    parser.add_argument("--jobs", type=jobs_arg, default=None, help="worker processes (default: all cores)")
    add_solver_arg(parser)
    add_backend_args(parser, "samples")
    parser.add_argument(
        "--timing-solves", type=count_arg, default=100, help="NMPC solves timed (default 100)"
    )
    parser.add_argument(
        "--min-pass-rate", type=unit_float_arg, default=0.95, help="pass rate needed in [0, 1] (default 0.95)"
    )
    parser.add_argument(
        "--payload-kg",
        type=payload_arg,
        nargs=2,
        metavar=("LOW", "HIGH"),
        default=None,
        help="payload range drawn, kg, at most the robot's maximum payload (default 0 to its "
        "all-terrain payload: for the Husky, Clearpath's rating for turning in place); check with "
        "the payload the robot will carry",
    )
    parser.add_argument(
        "--sensing-range-m",
        type=sensing_range_arg,
        nargs=2,
        metavar=("LOW", "HIGH"),
        default=None,
        help=f"lidar range drawn per sample, m, in [{MIN_SENSING_RANGE_M:g}, {MAX_SENSING_RANGE_M:g}] "
        "(default: not perturbed, the scenario's own range; the controller is told only of the "
        "obstacles the lidar sees)",
    )
    parser.add_argument(
        "--occlusion",
        action="store_true",
        help="every sample's lidar is occluded by static obstacles (default: the scenario's own setting)",
    )


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `check` and `check-table`."""
    check = sub.add_parser("check", help="sim-to-real checks before a Husky trial: audit + robustness sweep")
    check.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    _add_check_options(check)
    check.add_argument("--seed", type=seed_arg, default=None, help="perturbation seed >= 0")
    check.add_argument(
        "--out", type=path_arg, default=None, help="output directory (default results/check__...)"
    )
    check.set_defaults(func=cmd_check)

    table = sub.add_parser(
        "check-table", help="`check` over several scenarios and seeds, as one table (check_table.md)"
    )
    table.add_argument(
        "scenarios", nargs="*", help="scenario YAML paths or shipped names (default: every shipped one)"
    )
    _add_check_options(table)
    table.add_argument(
        "--seeds", type=seed_arg, nargs="+", default=[1, 2, 3], help="perturbation seeds (default 1 2 3)"
    )
    table.add_argument(
        "--out",
        type=path_arg,
        default=None,
        help="output directory (default results/check_table__CONTROLLER)",
    )
    table.set_defaults(func=cmd_check_table)
