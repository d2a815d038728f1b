"""`husky-sim run`: one scenario in PyBullet, its run folder, optionally its video."""

from __future__ import annotations

import argparse

from husky_sim import interrupts
from husky_sim.cli.common import (
    HORIZON_HELP,
    add_live_argument,
    add_solver_arg,
    announce_live,
    controller_choices,
    default_controller,
    horizon_arg,
    path_arg,
    seed_arg,
    unit_float_arg,
    warn_solve_budget,
)
from husky_sim.cli.render import add_render_arguments, options_from_args


def cmd_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.runs.run import run_scenario
    from husky_sim.runs.run_folder import default_run_dir
    from husky_sim.runs.scenario import load_scenario
    from husky_sim.viz.rendering import record_in_summary, render_run

    interrupts.check()  # the imports above take a second; a signal swallowed in them ends here
    sc = load_scenario(args.scenario).with_overrides(args.horizon, args.gamma, args.seed, args.solver)
    interrupts.check()  # loading builds the robot geometry (yourdfpy, trimesh)
    video = options_from_args(args) if args.video else None  # bad render options fail before the run
    horizon, gamma = sc.controller.horizon, sc.controller.gamma
    interrupts.begin_run()
    out = Path(args.out) if args.out else default_run_dir(sc.name, args.controller, horizon, gamma, sc.seed)
    announce_live(args)
    # creates `out` (or one-line error) first
    summary = run_scenario(sc, args.controller, out_dir=out, live_port=args.live)
    metrics = summary.metrics
    clearance = metrics.min_clearance_m
    clearance_text = "n/a" if clearance is None else f"{clearance:.3f} m"
    print(
        f"{sc.name} {args.controller} N={horizon} gamma={gamma:g}: {metrics.outcome}, "
        f"min clearance {clearance_text}, solve median {metrics.solve_ms_median:.2f} ms -> {out}"
    )
    warn_solve_budget(summary.as_dict())
    if video is not None:  # rendered afterwards from the written trace: it cannot touch the physics
        result = render_run(out, video)
        record_in_summary(out, result)
        print(result.report())
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `run`."""
    run = sub.add_parser("run", help="run one scenario in PyBullet; writes summary.json and log.csv")
    run.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    run.add_argument("--controller", choices=controller_choices(), default=default_controller())
    run.add_argument("--horizon", type=horizon_arg, default=None, help=HORIZON_HELP)
    run.add_argument("--gamma", type=unit_float_arg, default=None, help="CBF decay rate in [0, 1]")
    run.add_argument("--seed", type=seed_arg, default=None, help="noise and random-field seed")
    add_solver_arg(run)
    run.add_argument("--out", type=path_arg, default=None, help="output directory (default results/<run>)")
    run.add_argument("--video", action="store_true", help="then render OUT/video_CAMERA.mp4 from its trace")
    add_live_argument(run)
    add_render_arguments(run)
    run.set_defaults(func=cmd_run)
