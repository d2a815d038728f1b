"""`husky-sim` command line. User mistakes give one line on stderr and exit code 2; Ctrl-C and
SIGTERM exit 130 and 143 (husky_sim.interrupts), with what was run so far kept and marked
`interrupted`.

Heavy modules (CasADi, PyBullet's worlds, the scenario schema) are imported after the signal
handlers are installed, so an interrupt during start-up is honoured too.
"""

from __future__ import annotations

import argparse
import atexit
import math
import os
import sys
from collections.abc import Sequence

from husky_sim import interrupts

#: The controllers a command may choose (controllers.CONTROLLER_NAMES, without importing CasADi
#: before the signal handlers are in place; a test keeps the two equal).
CONTROLLER_CHOICES = ("none", "bt", "cbf", "relax-cbf", "husky-cbf")
#: The NLP solver backends (controllers.config.SOLVER_BACKENDS, likewise kept equal by a test).
SOLVER_CHOICES = ("fatrop", "ipopt", "opti")


class UsageError(Exception):
    """A user mistake: printed as one line, exit code 2."""


class _OneLineErrorParser(argparse.ArgumentParser):
    """argparse, but a usage mistake prints one line (no usage block) and exits 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _number_in(kind: type[int] | type[float], low: float, high: float):
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


def _path(text: str) -> str:
    """An argparse type: a non-empty path (an empty --out would silently mean the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    return text


#: Port of Foxglove's WebSocket server for --live (Foxglove's own default).
LIVE_PORT = 8765

#: Bounds of the command line's counts: what a 2-core machine (or a cluster) can reasonably run.
MAX_JOBS = 256
MAX_SAMPLES = 100_000
_horizon = _number_in(int, 1, 50)
_seed = _number_in(int, 0, 2**32 - 1)
_jobs = _number_in(int, 1, MAX_JOBS)
_count = _number_in(int, 1, MAX_SAMPLES)
_unit_float = _number_in(float, 0.0, 1.0)


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
        print(
            f"solve times on the same {args.steps} recorded closed-loop problems per cell "
            "(kinematic point stabilisation); CPU time is this thread's"
        )
        print(format_table(records))
    return 0


def _cmd_bench_sim(args: argparse.Namespace) -> int:
    from husky_sim.bench_sim import run_sim_bench

    print(run_sim_bench(duration_s=args.duration, solver=args.solver).report())
    if args.drive_table:
        from husky_sim.bench_sim import drive_table

        print("\nachieved versus commanded body velocity on flat ground (published drive limits)")
        print(drive_table())
    if args.turn_table:
        from husky_sim.bench_sim import turn_table

        print(
            "\nyaw rate achieved over check's payload x torque x friction corners "
            "(4 s held, mean of the last 2 s)"
        )
        print(turn_table())
    return 0


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from husky_sim.scenario import load_scenario, shipped_scenarios

    for path in shipped_scenarios():
        sc = load_scenario(str(path))
        print(f"{sc.name:34s} {sc.description}")
    return 0


def _warn(message: str) -> None:
    print(f"husky-sim: warning: {message}", file=sys.stderr)


def warn_solve_budget(summary: dict[str, object], label: str = "") -> None:
    """Say on stderr when solves took longer than tau (the summary says so too)."""
    over = summary.get("solves_over_budget") or 0
    if over:
        _warn(
            f"{label}{over} of {summary['steps']} solves took longer than tau = "
            f"{summary['solve_budget_ms']:g} ms (median {summary['solve_ms_median']:.1f} ms, max "
            f"{summary['solve_ms_max']:.1f} ms): on a robot those commands would arrive late"
        )


def _cmd_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.rendering import options_from_args, record_in_summary, render_run
    from husky_sim.run import default_run_dir, run_scenario
    from husky_sim.scenario import load_scenario

    interrupts.check()  # the imports above take a second; a signal swallowed in them ends here
    sc = load_scenario(args.scenario).with_overrides(args.horizon, args.gamma, args.seed)
    interrupts.check()  # loading builds the robot geometry (yourdfpy, trimesh)
    video = options_from_args(args) if args.video else None  # bad render options fail before the run
    horizon, gamma = sc.controller.horizon, sc.controller.gamma
    interrupts.begin_run()
    out = Path(args.out) if args.out else default_run_dir(sc.name, args.controller, horizon, gamma, sc.seed)
    _announce_live(args)
    # creates `out` (or one-line error) first
    summary = run_scenario(sc, args.controller, out_dir=out, live_port=args.live)
    clearance = summary["min_clearance_m"]
    clearance_text = "n/a" if clearance is None else f"{clearance:.3f} m"
    print(
        f"{sc.name} {args.controller} N={horizon} gamma={gamma:g}: {summary['outcome']}, "
        f"min clearance {clearance_text}, solve median {summary['solve_ms_median']:.2f} ms -> {out}"
    )
    warn_solve_budget(summary)
    if video is not None:  # rendered afterwards from the written trace: it cannot touch the physics
        result = render_run(out, video)
        record_in_summary(out, result)
        print(result.report())
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from husky_sim.rendering import options_from_args, render_run

    result = render_run(args.run_dir, options_from_args(args), args.out)
    print(result.report())
    return 0


def _cmd_suite(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.run import prepare_out_dir
    from husky_sim.scenario import load_scenario, shipped_scenarios
    from husky_sim.suite import markdown_table, matrix, run_suite, write_figures

    names = args.scenarios or [p.stem for p in shipped_scenarios()]
    for name in names:  # bad input fails here, in one line, before any worker starts
        sc = load_scenario(name)
        for horizon in args.horizons or [None]:
            for gamma in args.gammas or [None]:
                sc.with_overrides(horizon, gamma, args.seed)
    cells = matrix(names, args.controllers, args.horizons or [None], args.gammas or [None], args.seed)
    interrupts.begin_run()
    out = prepare_out_dir(Path(args.out))
    try:
        rows = run_suite(cells, jobs=args.jobs, out_dir=out, progress=not args.quiet)
    except interrupts.RunInterrupted:
        print(
            f"husky-sim: suite interrupted: no results.csv written; runs so far in {out / 'runs'}",
            file=sys.stderr,
        )
        raise
    for row in rows:
        warn_solve_budget(row, f"{row.get('run_dir') or row['scenario']}: ")
    figures = write_figures(rows, out, per_run=args.plots)
    print(markdown_table(rows), end="")
    print(f"{len(figures)} figures (PNG and SVG) -> {out / 'plots'}")
    errors = [r for r in rows if r["outcome"] == "error"]
    for r in errors:
        print(f"error in {r['run_dir']}: {r['error']}", file=sys.stderr)
    print(f"{len(rows)} runs -> {out / 'results.csv'}, {out / 'results.md'}")
    return 1 if errors else 0


def _cmd_check(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.check import CheckOptions, default_out_dir, run_check
    from husky_sim.run import prepare_out_dir
    from husky_sim.scenario import load_scenario

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
    )
    sc = load_scenario(args.scenario)
    horizon = sc.with_overrides(horizon=args.horizon).controller.horizon  # range-checked here
    seed = sc.seed if args.seed is None else args.seed
    interrupts.begin_run()  # workers are stopped, not orphaned, on a signal
    out = prepare_out_dir(
        Path(args.out or default_out_dir(sc.name, args.controller, horizon, args.samples, seed))
    )
    report = run_check(sc, options, out, log=print)
    s = report.stats
    print(f"sweep: {s['passed']}/{s['samples']} passed ({s['pass_rate']:.0%}), outcomes {s['outcomes']}")
    print(f"{report.verdict}: {report.reason}")
    print(f"-> {out / 'check.md'}, {out / 'check.json'}")
    return 0 if report.verdict == "PASS" else 1


def _cmd_plot(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.plots import RUN_FIGURES, plot_runs, plot_tuning_maps

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


def _cmd_paper(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.claims import run_paper_report
    from husky_sim.run import prepare_out_dir

    interrupts.begin_run()  # workers are stopped, not orphaned, on a signal
    out = prepare_out_dir(Path(args.out))
    results = run_paper_report(out, jobs=args.jobs, progress=not args.quiet)
    for r in results:
        print(f"{r.kinematic.verdict:>15s} | {r.physics.verdict:>15s} | {r.claim}")
    print(f"(kinematic | PyBullet) -> {out / 'claims.md'}")
    return 0


def _cmd_identify(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.yaw_response import DEFAULT_FILE, identify_in_simulation, write_identification

    identification = identify_in_simulation()
    print("\n".join(identification.lines()))
    out = Path(args.out) if args.out else DEFAULT_FILE
    command = "husky-sim identify" + ("" if args.out is None else f" --out {args.out}")
    try:
        write_identification(identification, out, command)
    except OSError as exc:
        raise UsageError(f"identify: cannot write {out} ({exc.strerror or exc})") from None
    print(f"-> {out}")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.replay import run_replay

    bag = Path(args.bag)
    out = Path(args.out) if args.out else Path("results") / f"replay__{bag.stem or 'bag'}"
    lines = run_replay(
        bag,
        out,
        cmd_topic=args.cmd_topic,
        odom_topic=args.odom_topic,
        multiplier=args.wheel_separation_multiplier,
        ground_friction=args.ground_friction,
        do_fit=args.fit,
    )
    print("\n".join(lines))
    return 0


def _ros2_settings(args: argparse.Namespace, **fixed: object):
    """Ros2Settings from the command line's topic, frame and domain options."""
    from dataclasses import fields

    from husky_sim.ros2.settings import Ros2Settings

    given = {
        f.name: getattr(args, f.name) for f in fields(Ros2Settings) if getattr(args, f.name, None) is not None
    }
    return Ros2Settings(**{**given, **fixed})


def _add_ros2_arguments(parser: argparse.ArgumentParser) -> None:
    from dataclasses import fields

    from husky_sim.ros2.settings import MAX_DOMAIN_ID, QOS_PROFILE_NAMES, Ros2Settings

    for f in fields(Ros2Settings):
        flag = "--" + f.name.replace("_", "-")
        if f.name.endswith(("_topic", "_frame")):
            parser.add_argument(flag, default=None, help=f"default {f.default}")
        elif f.name.endswith("_qos"):
            parser.add_argument(flag, choices=QOS_PROFILE_NAMES, default=None, help=f"default {f.default}")
    parser.add_argument(
        "--domain-id",
        type=_number_in(int, 0, MAX_DOMAIN_ID),
        default=None,
        help=f"DDS domain in [0, {MAX_DOMAIN_ID}] (default: ROS_DOMAIN_ID, else 0)",
    )


def _add_live_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--live",
        type=_number_in(int, 1, 65535),
        nargs="?",
        const=LIVE_PORT,
        default=None,
        metavar="PORT",
        help=f"also stream the run to Foxglove's WebSocket server on 127.0.0.1:PORT (default {LIVE_PORT})",
    )


def _announce_live(args: argparse.Namespace) -> None:
    if args.live is not None:
        print(f"streaming to Foxglove: open ws://127.0.0.1:{args.live} in Foxglove", flush=True)


def _cmd_serve(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.ros2.node import serve
    from husky_sim.run import default_run_dir
    from husky_sim.scenario import load_scenario

    interrupts.check()
    sc = load_scenario(args.scenario).with_overrides(args.horizon, args.gamma, None)
    settings = _ros2_settings(args, use_sim_time=args.use_sim_time, localhost_only=args.localhost_only)
    domain = settings.resolved_domain_id()  # a bad ROS_DOMAIN_ID is a one-line error before anything runs
    if args.solve_budget is not None and args.solve_budget > sc.tau_s:
        raise UsageError(f"--solve-budget: must be at most tau = {sc.tau_s:g} s, got {args.solve_budget:g}")
    controller = sc.make_controller(args.controller)
    interrupts.begin_run()
    horizon, gamma = sc.controller.horizon, sc.controller.gamma
    out = (
        Path(args.out)
        if args.out
        else default_run_dir(sc.name, args.controller, horizon, gamma, sc.seed, "serve")
    )
    print(
        f"serving {args.controller} N={horizon} on DDS domain {domain}: {settings.odometry_topic} + "
        f"{settings.obstacles_topic} + {settings.goal_topic} -> {settings.cmd_vel_topic} "
        f"every {sc.tau_s:g} s ({'sim' if settings.use_sim_time else 'wall'} clock); log -> {out}",
        flush=True,
    )
    try:
        stats = serve(
            controller, sc.reference_object(), sc.tau_s, settings, out, args.duration, args.solve_budget
        )
        reason = f"after {args.duration:g} s"
    except interrupts.RunInterrupted as exc:  # the normal way to stop a node: it has sent a zero command
        import signal

        reason = f"by {signal.Signals(exc.signum).name}"
        interrupts.reset()
        stats = None
    print(f"node stopped {reason} with a zero command; counts in {out / 'serve_summary.json'}")
    if stats is not None:
        print(", ".join(f"{k} {v}" for k, v in stats.events.items()))
    return 0


def _cmd_rehearse(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.ros2.rehearse import rehearse
    from husky_sim.run import default_run_dir
    from husky_sim.scenario import load_scenario

    interrupts.check()
    sc = load_scenario(args.scenario).with_overrides(args.horizon, args.gamma, args.seed)
    horizon, gamma = sc.controller.horizon, sc.controller.gamma
    interrupts.begin_run()
    out = (
        Path(args.out)
        if args.out
        else default_run_dir(sc.name, args.controller, horizon, gamma, sc.seed, "rehearse")
    )
    _announce_live(args)
    summary = rehearse(sc, args.controller, out, args.domain_id, args.reply_timeout, live_port=args.live)
    transport = summary["transport"]
    latency = transport["cmd_vel_latency_ms"]
    latency_text = (
        "n/a" if latency["median"] is None else f"{latency['median']:.2f} ms (p99 {latency['p99']:.2f})"
    )
    clearance = summary["min_clearance_m"]
    print(
        f"{sc.name} {args.controller} N={horizon} over DDS: {summary['outcome']}, min clearance "
        f"{'n/a' if clearance is None else f'{clearance:.3f} m'}, /cmd_vel latency median {latency_text}, "
        f"{transport['reply_timeouts']} replies missing -> {out}"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    from husky_sim.rendering import add_render_arguments
    from husky_sim.ros2.settings import MAX_DOMAIN_ID

    parser = _OneLineErrorParser(prog="husky-sim", description="Husky A200 NMPC-CLF/CBF validation suite")
    sub = parser.add_subparsers(dest="command", required=True)
    scenarios = sub.add_parser("scenarios", help="list the shipped scenarios")
    scenarios.set_defaults(func=_cmd_scenarios)
    run = sub.add_parser("run", help="run one scenario in PyBullet; writes summary.json and log.csv")
    run.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    run.add_argument("--controller", choices=CONTROLLER_CHOICES, default="relax-cbf")
    run.add_argument("--horizon", type=_horizon, default=None, help="prediction steps N in [1, 50]")
    run.add_argument("--gamma", type=_unit_float, default=None, help="CBF decay rate in [0, 1]")
    run.add_argument("--seed", type=_seed, default=None, help="noise and random-field seed")
    run.add_argument("--out", type=_path, default=None, help="output directory (default results/<run>)")
    run.add_argument("--video", action="store_true", help="then render OUT/video_CAMERA.mp4 from its trace")
    _add_live_argument(run)
    add_render_arguments(run)
    run.set_defaults(func=_cmd_run)
    serve = sub.add_parser(
        "serve",
        help="run a controller as a ROS 2 node over DDS: odometry, goal, obstacles in; /cmd_vel, /plan out",
    )
    serve.add_argument(
        "scenario", help="a scenario YAML path or shipped name: the controller's parameters and reference"
    )
    serve.add_argument("--controller", choices=CONTROLLER_CHOICES, default="husky-cbf")
    serve.add_argument("--horizon", type=_horizon, default=None, help="prediction steps N in [1, 50]")
    serve.add_argument("--gamma", type=_unit_float, default=None, help="CBF decay rate in [0, 1]")
    serve.add_argument("--out", type=_path, default=None, help="folder for serve.csv and serve_summary.json")
    serve.add_argument(
        "--duration", type=_number_in(float, 0.0, 1e7), default=None, help="stop after this many s"
    )
    serve.add_argument(
        "--solve-budget",
        type=_number_in(float, 1e-6, 10.0),
        default=None,
        help="s; a slower solve is dropped and a zero command sent (default tau; at most tau)",
    )
    serve.add_argument("--use-sim-time", action="store_true", help="the node's clock is /clock (a simulator)")
    serve.add_argument("--localhost-only", action="store_true", help="keep DDS traffic on 127.0.0.1")
    _add_ros2_arguments(serve)
    serve.set_defaults(func=_cmd_serve)
    rehearse = sub.add_parser(
        "rehearse", help="drive the PyBullet Husky from a `serve` node in another process, over DDS"
    )
    rehearse.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    rehearse.add_argument("--controller", choices=CONTROLLER_CHOICES, default="husky-cbf")
    rehearse.add_argument("--horizon", type=_horizon, default=None, help="prediction steps N in [1, 50]")
    rehearse.add_argument("--gamma", type=_unit_float, default=None, help="CBF decay rate in [0, 1]")
    rehearse.add_argument("--seed", type=_seed, default=None, help="noise and random-field seed")
    rehearse.add_argument(
        "--out", type=_path, default=None, help="output directory (default results/rehearse__<run>)"
    )
    rehearse.add_argument(
        "--domain-id",
        type=_number_in(int, 0, MAX_DOMAIN_ID),
        default=None,
        help=f"DDS domain in [0, {MAX_DOMAIN_ID}] (default: the first free of 100 to 199 on this machine)",
    )
    rehearse.add_argument(
        "--reply-timeout", type=_number_in(float, 0.01, 600.0), default=10.0,
        help="wall s to wait for each /cmd_vel before braking (counted)",
    )  # fmt: skip
    _add_live_argument(rehearse)
    rehearse.set_defaults(func=_cmd_rehearse)
    render = sub.add_parser("render", help="render a recorded run directory to an MP4 (no re-solve)")
    render.add_argument("run_dir", help="a directory written by `husky-sim run` (needs its trace.npz)")
    render.add_argument(
        "--out", type=_path, default=None, help="video file, .mp4 (default RUN_DIR/video_CAMERA.mp4)"
    )
    add_render_arguments(render)
    render.set_defaults(func=_cmd_render)
    suite = sub.add_parser("suite", help="run a scenario x controller x horizon x gamma matrix in parallel")
    suite.add_argument("--scenarios", nargs="+", default=None, help="names or paths (default: all shipped)")
    suite.add_argument(
        "--controllers", nargs="+", choices=CONTROLLER_CHOICES, default=["bt", "cbf", "relax-cbf"]
    )
    suite.add_argument("--horizons", nargs="+", type=_horizon, default=None, help="default: file's N")
    suite.add_argument("--gammas", nargs="+", type=_unit_float, default=None, help="default: file's gamma")
    suite.add_argument("--seed", type=_seed, default=None, help="seed (default: the file's)")
    suite.add_argument("--jobs", type=_jobs, default=2, help="worker processes (default 2)")
    suite.add_argument(
        "--out", type=_path, default="results/suite", help="output directory (default results/suite)"
    )
    suite.add_argument("--quiet", action="store_true", help="no progress bar")
    suite.add_argument("--plots", action="store_true", help="also every run's own figures")
    suite.set_defaults(func=_cmd_suite)
    paper = sub.add_parser("paper", help="check the paper's claims; writes claims.md")
    paper.add_argument(
        "--out", type=_path, default="results/paper", help="output directory (default results/paper)"
    )
    paper.add_argument("--jobs", type=_jobs, default=2, help="worker processes (default 2)")
    paper.add_argument("--quiet", action="store_true", help="no progress bar")
    paper.set_defaults(func=_cmd_paper)
    bench = sub.add_parser(
        "bench", help="NMPC solve times of every solver backend on the same recorded closed-loop problems"
    )
    bench.add_argument("--json", action="store_true", help="print JSON records instead of a table")
    bench.add_argument("--steps", type=_count, default=150, help="control steps per cell (default 150)")
    paper = CONTROLLER_CHOICES[:4]  # the bench times the paper's OCP (husky-cbf: `run` reports its times)
    bench.add_argument("--variants", nargs="+", choices=paper, default=list(paper))
    bench.add_argument("--horizons", nargs="+", type=_horizon, default=[5, 7, 12])
    bench.add_argument(
        "--obstacles", nargs="+", type=int, choices=range(1, 8), default=[1, 7], metavar="{1..7}"
    )
    bench.add_argument("--solvers", nargs="+", choices=SOLVER_CHOICES, default=list(SOLVER_CHOICES))
    bench.add_argument(
        "--gamma", type=_unit_float, default=0.1, help="CBF decay rate in [0, 1] (default 0.1)"
    )
    bench.set_defaults(func=_cmd_bench)
    bench_sim = sub.add_parser("bench-sim", help="PyBullet real-time factor and peak memory")
    bench_sim.add_argument(
        "--duration",
        type=_number_in(float, 0.1, 600.0),
        default=30.0,
        help="episode length in s, 0.1 to 600 (default 30)",
    )
    bench_sim.add_argument(
        "--solver",
        choices=SOLVER_CHOICES[:2],
        default=None,
        help="NLP backend of the episode (default: SolverOptions.backend)",
    )
    bench_sim.add_argument(
        "--drive-table", action="store_true", help="also print achieved vs commanded v and omega"
    )
    bench_sim.add_argument(
        "--turn-table",
        action="store_true",
        help="also print the yaw rate achieved with payload, torque, friction",
    )
    bench_sim.set_defaults(func=_cmd_bench_sim)
    check = sub.add_parser("check", help="sim-to-real checks before a Husky trial: audit + robustness sweep")
    check.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    check.add_argument("--controller", choices=CONTROLLER_CHOICES, default="relax-cbf")
    check.add_argument(
        "--horizon", type=_horizon, default=None, help="prediction steps N (default: the file's)"
    )
    check.add_argument("--samples", type=_count, default=32, help="perturbed runs K >= 1 (default 32)")
    check.add_argument("--jobs", type=_jobs, default=None, help="worker processes (default: all cores)")
    check.add_argument("--seed", type=_seed, default=None, help="perturbation seed >= 0")
    check.add_argument("--backend", choices=("local", "dask"), default="local", help="where samples run")
    check.add_argument("--scheduler", default=None, help="Dask scheduler address (default: a LocalCluster)")
    check.add_argument("--timing-solves", type=_count, default=100, help="NMPC solves timed (default 100)")
    check.add_argument(
        "--min-pass-rate", type=_unit_float, default=0.95, help="pass rate needed in [0, 1] (default 0.95)"
    )
    check.add_argument(
        "--out", type=_path, default=None, help="output directory (default results/check__...)"
    )
    check.set_defaults(func=_cmd_check)
    plot = sub.add_parser("plot", help="figures of runs (PNG and SVG), or tuning maps of a suite")
    plot.add_argument("run_dirs", nargs="*", metavar="RUN_DIR", help="run directories (husky-sim run --out)")
    plot.add_argument("--results", default=None, help="a suite's results.csv: gamma x N tuning maps")
    plot.add_argument("--scenario", default=None, help="with --results: only this scenario's maps")
    plot.add_argument(
        "--out",
        type=_path,
        default=None,
        help="output directory (default RUN_DIR/plots, or beside results.csv)",
    )
    plot.set_defaults(func=_cmd_plot)
    identify = sub.add_parser(
        "identify", help="fit the simulated Husky's yaw-rate lag (gain, time constant) to step commands"
    )
    identify.add_argument(
        "--out",
        type=_path,
        default=None,
        help="YAML file to write (default assets/husky_a200/yaw_response.yaml, the scenarios' default)",
    )
    identify.set_defaults(func=_cmd_identify)
    replay = sub.add_parser(
        "replay", help="drive the simulated Husky with a recording's commands; measure the divergence"
    )
    replay.add_argument("bag", help="a ROS 1 .bag, a ROS 2 bag directory, or a CSV t,v,omega,x,y,theta")
    replay.add_argument("--cmd-topic", default="/cmd_vel", help="Twist or TwistStamped (default /cmd_vel)")
    replay.add_argument(
        "--odom-topic", default="/odometry/filtered", help="nav_msgs/Odometry (default /odometry/filtered)"
    )
    replay.add_argument(
        "--out", type=_path, default=None, help="output directory (default results/replay__<bag>)"
    )
    replay.add_argument(
        "--fit", action="store_true", help="fit the multiplier and ground friction not given below to the ATE"
    )
    replay.add_argument(
        "--wheel-separation-multiplier",
        type=_number_in(float, 0.5, 5.0),
        default=None,
        metavar="M",
        help="default 1.875",
    )
    replay.add_argument(
        "--ground-friction", type=_number_in(float, 0.01, 5.0), default=None, metavar="MU", help="default 1.0"
    )
    replay.set_defaults(func=_cmd_replay)
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
        return _run_command(argv)
    finally:
        interrupts.restore(previous)


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
    except (UsageError, ValueError) as exc:  # ConfigError and ScenarioError are ValueErrors
        print(f"husky-sim: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `husky-sim scenarios | head`: the reader left, nothing to report
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as exc:  # the machine, not the user: a full disk, a vanished directory
        print(f"husky-sim: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    signum = interrupts.pending()  # a signal a library swallowed still ends the command as one
    return _interrupted(signum) if signum is not None else code


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


if __name__ == "__main__":
    entry()
