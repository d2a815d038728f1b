"""`husky-sim bench` (solve times per backend), `bench-sim` (closed-loop real-time factor),
`bench-campaign` (a campaign's real-time factors and controller step times) and
`bench-divergence` (where FATROP's and IPOPT's closed loops part on one cell)."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import (
    HORIZON_HELP,
    SOLVER_CHOICES,
    controller_choices,
    count_arg,
    horizon_arg,
    number_in,
    unit_float_arg,
)


def cmd_bench(args: argparse.Namespace) -> int:
    from husky_sim.bench.solvers import format_table, records_json, run_bench

    records = run_bench(
        controllers=args.controllers,
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
        print(
            f"solve times on the same {args.steps} recorded closed-loop problems per cell "
            "(kinematic point stabilisation); CPU time is this thread's"
        )
        print(format_table(records))
    return 0


def cmd_bench_sim(args: argparse.Namespace) -> int:
    from husky_sim.bench.closed_loop import run_large_world_bench, run_sim_bench

    if args.world in ("small", "both"):
        small_s = 30.0 if args.duration is None else args.duration
        print(run_sim_bench(duration_s=small_s, solver=args.solver).report())
    if args.world in ("large", "both"):
        large = run_large_world_bench(args.controller, duration_s=args.duration, solver=args.solver)
        print(large.report())
    if args.drive_table:
        from husky_sim.bench.closed_loop import drive_table

        print("\nachieved versus commanded body velocity on flat ground (published drive limits)")
        print(drive_table())
    if args.turn_table:
        from husky_sim.bench.closed_loop import turn_table

        print(
            "\nyaw rate achieved over check's payload x torque x friction corners "
            "(4 s held, mean of the last 2 s)"
        )
        print(turn_table())
    return 0


def cmd_bench_campaign(args: argparse.Namespace) -> int:
    from husky_sim.bench.campaign_speed import campaign_speed

    for folder in args.folders:
        print(campaign_speed(folder).report())
    return 0


def cmd_bench_divergence(args: argparse.Namespace) -> int:
    from husky_sim.bench.divergence import trace_divergence
    from husky_sim.runs.scenario import load_scenario

    sc = load_scenario(args.scenario).with_overrides(args.horizon, args.gamma)
    print(trace_divergence(sc, args.controller).report())
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `bench`, `bench-sim`, `bench-campaign`, `bench-divergence`."""
    bench = sub.add_parser(
        "bench", help="NMPC solve times of every solver backend on the same recorded closed-loop problems"
    )
    bench.add_argument("--json", action="store_true", help="print JSON records instead of a table")
    bench.add_argument("--steps", type=count_arg, default=150, help="control steps per cell (default 150)")
    paper = controller_choices(
        paper_only=True
    )  # the bench times the paper's OCP (husky-cbf: `run` reports its times)
    bench.add_argument(
        "--controllers", nargs="+", choices=paper, default=list(paper), help="the paper's (default: all four)"
    )
    bench.add_argument("--horizons", nargs="+", type=horizon_arg, default=[5, 7, 12])
    bench.add_argument(
        "--obstacles", nargs="+", type=int, choices=range(1, 8), default=[1, 7], metavar="{1..7}"
    )
    bench.add_argument("--solvers", nargs="+", choices=SOLVER_CHOICES, default=list(SOLVER_CHOICES))
    bench.add_argument(
        "--gamma", type=unit_float_arg, default=0.1, help="CBF decay rate in [0, 1] (default 0.1)"
    )
    bench.set_defaults(func=cmd_bench)
    bench_sim = sub.add_parser(
        "bench-sim",
        help="PyBullet real-time factor with 8 and with 1,000 obstacles, solve and physics step "
        "times, and peak memory",
    )
    bench_sim.add_argument(
        "--duration",
        type=number_in(float, 0.1, 600.0),
        default=None,
        help="episode length in s, 0.1 to 600 (default: 30 for the small world; the large world's "
        "own 60, which ends once it is decided)",
    )
    bench_sim.add_argument(
        "--solver",
        choices=SOLVER_CHOICES[:2],
        default=None,
        help="NLP backend of the episode (default: SolverOptions.backend)",
    )
    bench_sim.add_argument(
        "--world",
        choices=("both", "small", "large"),
        default="both",
        help="small: 8 obstacles (relax-cbf); large: 1,000 static ones "
        "(scenarios/large/large_world_1000.yaml); default both",
    )
    bench_sim.add_argument(
        "--controller",
        choices=controller_choices(),
        default="husky-cbf",
        help="the large world's controller (default husky-cbf)",
    )
    bench_sim.add_argument(
        "--drive-table", action="store_true", help="also print achieved vs commanded v and omega"
    )
    bench_sim.add_argument(
        "--turn-table",
        action="store_true",
        help="also print the yaw rate achieved with payload, torque, friction",
    )
    bench_sim.set_defaults(func=cmd_bench_sim)
    bench_campaign = sub.add_parser(
        "bench-campaign",
        help="a campaign's closed-loop real-time factor (median over its runs) and controller step "
        "time (median, p99 over every step), against the targets 10x and 25 ms",
    )
    bench_campaign.add_argument("folders", nargs="+", help="`husky-sim campaign` output folders")
    bench_campaign.set_defaults(func=cmd_bench_campaign)
    divergence = sub.add_parser(
        "bench-divergence",
        help="where one PyBullet cell's FATROP and IPOPT closed loops part, and whether that is a "
        "different local optimum",
    )
    divergence.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    divergence.add_argument(
        "--controller", choices=controller_choices(paper_only=True, with_baseline=False), default="cbf"
    )
    divergence.add_argument("--horizon", type=horizon_arg, default=None, help=HORIZON_HELP)
    divergence.add_argument("--gamma", type=unit_float_arg, default=None, help="CBF decay rate in [0, 1]")
    divergence.set_defaults(func=cmd_bench_divergence)
