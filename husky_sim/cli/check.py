"""`husky-sim check`: audit + robustness sweep -> PASS / FAIL before a Husky trial."""

from __future__ import annotations

import argparse

from husky_sim import interrupts
from husky_sim.cli.common import (
    add_backend_args,
    add_solver_arg,
    controller_choices,
    count_arg,
    default_controller,
    horizon_arg,
    jobs_arg,
    path_arg,
    payload_arg,
    seed_arg,
    unit_float_arg,
)


def cmd_check(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.realcheck.check import CheckOptions, run_check
    from husky_sim.realcheck.sweep import PerturbationRanges
    from husky_sim.runs.run_folder import default_check_dir, prepare_out_dir
    from husky_sim.runs.scenario import load_scenario

    # integers are range-checked by CheckOptions, so "--samples 0" is one line, exit 2
    options = CheckOptions(
        controller=args.controller,
        horizon=args.horizon,
        samples=args.samples,
        seed=args.seed,
        jobs=args.jobs,
        backend=args.backend,
        scheduler=args.scheduler,
        timing_solves=args.timing_solves,
        min_pass_rate=args.min_pass_rate,
        ranges=PerturbationRanges()
        if args.payload_kg is None
        else PerturbationRanges(payload_kg=tuple(args.payload_kg)),
    )
    sc = load_scenario(args.scenario).with_overrides(solver=args.solver)
    horizon = sc.with_overrides(horizon=args.horizon).controller.horizon  # range-checked here
    seed = sc.seed if args.seed is None else args.seed
    options.ranges.for_robot(sc.robot.description())  # a payload the robot cannot carry: refused here
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


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `check`."""
    check = sub.add_parser("check", help="sim-to-real checks before a Husky trial: audit + robustness sweep")
    check.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    check.add_argument("--controller", choices=controller_choices(), default=default_controller())
    check.add_argument(
        "--horizon", type=horizon_arg, default=None, help="prediction steps N (default: the file's)"
    )
    check.add_argument("--samples", type=count_arg, default=32, help="perturbed runs K >= 1 (default 32)")
    check.add_argument("--jobs", type=jobs_arg, default=None, help="worker processes (default: all cores)")
    check.add_argument("--seed", type=seed_arg, default=None, help="perturbation seed >= 0")
    add_solver_arg(check)
    add_backend_args(check, "samples")
    check.add_argument("--timing-solves", type=count_arg, default=100, help="NMPC solves timed (default 100)")
    check.add_argument(
        "--min-pass-rate", type=unit_float_arg, default=0.95, help="pass rate needed in [0, 1] (default 0.95)"
    )
    check.add_argument(
        "--payload-kg",
        type=payload_arg,
        nargs=2,
        metavar=("LOW", "HIGH"),
        default=None,
        help="payload range drawn, kg, at most the robot's maximum payload (default 0 to its "
        "all-terrain payload: for the Husky, Clearpath's rating for turning in place); check with "
        "the payload the robot will carry",
    )
    check.add_argument(
        "--out", type=path_arg, default=None, help="output directory (default results/check__...)"
    )
    check.set_defaults(func=cmd_check)
