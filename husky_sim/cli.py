"""`husky-sim` command line. User mistakes give one line on stderr and exit code 2."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from controllers import SAFETY_CONSTRAINTS, ConfigError
from husky_sim.scenario import ScenarioError


class UsageError(Exception):
    """A user mistake: printed as one line, exit code 2."""


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


def _unit_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {value}")
    return value


def _cmd_bench(args: argparse.Namespace) -> int:
    from husky_sim.bench import format_table, records_json, run_bench

    records = run_bench(
        variants=args.variants,
        horizons=args.horizons,
        obstacle_counts=args.obstacles,
        solvers=args.solvers,
        steps=args.steps,
        gamma=args.gamma,
        progress=not args.json,
    )
    if args.json:
        print(records_json(records))
    else:
        print(f"closed-loop solve times over {args.steps} control steps (kinematic point stabilisation)")
        print(format_table(records))
    return 0


def _cmd_bench_sim(args: argparse.Namespace) -> int:
    from husky_sim.bench_sim import run_sim_bench

    print(run_sim_bench(duration_s=args.duration).report())
    if args.drive_table:
        from husky_sim.bench_sim import drive_table

        print("\nachieved versus commanded body velocity on flat ground (published drive limits)")
        print(drive_table())
    return 0


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from husky_sim.scenario import load_scenario, shipped_scenarios

    for path in shipped_scenarios():
        sc = load_scenario(str(path))
        print(f"{sc.name:34s} {sc.description}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.run import run_dir_name, run_scenario
    from husky_sim.scenario import load_scenario

    sc = load_scenario(args.scenario)
    horizon = args.horizon or sc.controller.horizon
    gamma = sc.controller.gamma if args.gamma is None else args.gamma
    seed = sc.seed if args.seed is None else args.seed
    out = (
        Path(args.out)
        if args.out
        else Path("results") / run_dir_name(sc.name, args.controller, horizon, gamma, seed)
    )
    summary = run_scenario(sc, args.controller, horizon, gamma, seed, out)
    clearance = summary["min_clearance_m"]
    clearance_text = "n/a" if clearance is None else f"{clearance:.3f} m"
    print(
        f"{sc.name} {args.controller} N={horizon} gamma={gamma:g}: {summary['outcome']}, "
        f"min clearance {clearance_text}, solve median {summary['solve_ms_median']:.2f} ms -> {out}"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="husky-sim", description="Husky A200 NMPC-CLF/CBF validation suite")
    sub = parser.add_subparsers(dest="command", required=True)
    scenarios = sub.add_parser("scenarios", help="list the shipped scenarios")
    scenarios.set_defaults(func=_cmd_scenarios)
    run = sub.add_parser("run", help="run one scenario in PyBullet; writes summary.json and log.csv")
    run.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    run.add_argument("--controller", choices=SAFETY_CONSTRAINTS, default="relax-cbf")
    run.add_argument("--horizon", type=_positive_int, default=None, help="prediction steps N >= 1")
    run.add_argument("--gamma", type=_unit_float, default=None, help="CBF decay rate in [0, 1]")
    run.add_argument("--seed", type=int, default=None, help="seed of noise and random obstacles")
    run.add_argument("--out", default=None, help="output directory (default results/<run>)")
    run.set_defaults(func=_cmd_run)
    bench = sub.add_parser("bench", help="NMPC solve-time benchmark: ours vs a casadi.Opti baseline")
    bench.add_argument("--json", action="store_true", help="print JSON records instead of a table")
    bench.add_argument(
        "--steps", type=_positive_int, default=150, help="control steps per cell (default 150)"
    )
    bench.add_argument("--variants", nargs="+", choices=SAFETY_CONSTRAINTS, default=list(SAFETY_CONSTRAINTS))
    bench.add_argument("--horizons", nargs="+", type=_positive_int, default=[5, 7, 12])
    bench.add_argument(
        "--obstacles", nargs="+", type=int, choices=range(1, 8), default=[1, 7], metavar="{1..7}"
    )
    bench.add_argument("--solvers", nargs="+", choices=("nlpsol", "opti"), default=["nlpsol", "opti"])
    bench.add_argument(
        "--gamma", type=_unit_float, default=0.1, help="CBF decay rate in [0, 1] (default 0.1)"
    )
    bench.set_defaults(func=_cmd_bench)
    bench_sim = sub.add_parser("bench-sim", help="PyBullet real-time factor and peak memory")
    bench_sim.add_argument("--duration", type=float, default=30.0, help="episode length in s (default 30)")
    bench_sim.add_argument(
        "--drive-table", action="store_true", help="also print achieved vs commanded v and omega"
    )
    bench_sim.set_defaults(func=_cmd_bench_sim)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (UsageError, ConfigError, ScenarioError, ValueError) as exc:
        print(f"husky-sim: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("husky-sim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
