"""`husky-sim serve` (a controller as a ROS 2 node over DDS) and `husky-sim rehearse` (the PyBullet
Husky driven by such a node in another process)."""

from __future__ import annotations

import argparse

from husky_sim import interrupts
from husky_sim.cli.common import (
    HORIZON_HELP,
    UsageError,
    add_live_argument,
    announce_live,
    controller_choices,
    default_controller,
    horizon_arg,
    number_in,
    path_arg,
    seed_arg,
    unit_float_arg,
)


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

    from husky_sim.ros2.settings import MAX_DOMAIN_ID, QOS_PROFILE_NAMES, ROS_DISTRO_NAMES, Ros2Settings

    for f in fields(Ros2Settings):
        flag = "--" + f.name.replace("_", "-")
        if f.name.endswith(("_topic", "_frame")) or f.name == "node_name":
            parser.add_argument(flag, default=None, help=f"default {f.default}")
        elif f.name.endswith("_qos"):
            parser.add_argument(flag, choices=QOS_PROFILE_NAMES, default=None, help=f"default {f.default}")
    parser.add_argument(
        "--ros-distro",
        choices=ROS_DISTRO_NAMES,
        default=None,
        help="the ROS 2 distribution whose graph layout the node announces in (Humble's gids are "
        "24 bytes, later ones' 16; Cyclone DDS transport); default: the peers', from discovery data",
    )
    parser.add_argument(
        "--cmd-vel-stamped",
        action="store_true",
        default=None,
        help="publish geometry_msgs/TwistStamped (Jazzy's diff-drive controllers take it)",
    )
    parser.add_argument(
        "--domain-id",
        type=number_in(int, 0, MAX_DOMAIN_ID),
        default=None,
        help=f"DDS domain in [0, {MAX_DOMAIN_ID}] (default: ROS_DOMAIN_ID, else 0)",
    )


def _add_transport_argument(parser: argparse.ArgumentParser) -> None:
    from husky_sim.ros2.settings import TRANSPORTS

    parser.add_argument(
        "--transport",
        choices=TRANSPORTS,
        default=TRANSPORTS[0],
        help="the node's transport: Cyclone DDS from Python (no ROS install), or rclpy on the "
        "middleware ROS 2 is configured for (settings become ROS parameters)",
    )


def cmd_serve(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.ros2.node import serve
    from husky_sim.runs.run_folder import default_run_dir
    from husky_sim.runs.scenario import load_scenario

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
    if args.ros_args and args.transport != "rclpy":
        raise UsageError("--ros-args: only the rclpy transport takes ROS arguments (--transport rclpy)")
    print(
        f"serving {args.controller} N={horizon} over {args.transport} on DDS domain {domain}: "
        f"{settings.odometry_topic} + "
        f"{settings.obstacles_topic} + {settings.goal_topic} -> {settings.cmd_vel_topic} "
        f"every {sc.tau_s:g} s ({'sim' if settings.use_sim_time else 'wall'} clock); log -> {out}",
        flush=True,
    )
    try:
        stats = serve(
            controller,
            sc.reference_object(),
            sc.tau_s,
            settings,
            out,
            args.duration,
            args.solve_budget,
            args.transport,
            args.ros_args or (),
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


def cmd_rehearse(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.ros2.rehearse import rehearse
    from husky_sim.runs.run_folder import default_run_dir
    from husky_sim.runs.scenario import load_scenario

    interrupts.check()
    sc = load_scenario(args.scenario).with_overrides(args.horizon, args.gamma, args.seed)
    horizon, gamma = sc.controller.horizon, sc.controller.gamma
    interrupts.begin_run()
    out = (
        Path(args.out)
        if args.out
        else default_run_dir(sc.name, args.controller, horizon, gamma, sc.seed, "rehearse")
    )
    announce_live(args)
    summary = rehearse(
        sc,
        args.controller,
        out,
        args.domain_id,
        args.reply_timeout,
        live_port=args.live,
        transport=args.transport,
        cmd_vel_stamped=args.cmd_vel_stamped,
    )
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


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `serve`, `rehearse`."""
    from husky_sim.ros2.settings import MAX_DOMAIN_ID

    serve = sub.add_parser(
        "serve",
        help="run a controller as a ROS 2 node over DDS: odometry, goal, obstacles in; /cmd_vel, /plan out",
    )
    serve.add_argument(
        "scenario", help="a scenario YAML path or shipped name: the controller's parameters and reference"
    )
    serve.add_argument(
        "--controller", choices=controller_choices(), default=default_controller(on_robot=True)
    )
    serve.add_argument("--horizon", type=horizon_arg, default=None, help=HORIZON_HELP)
    serve.add_argument("--gamma", type=unit_float_arg, default=None, help="CBF decay rate in [0, 1]")
    serve.add_argument(
        "--out", type=path_arg, default=None, help="folder for serve.csv and serve_summary.json"
    )
    serve.add_argument(
        "--duration", type=number_in(float, 0.0, 1e7), default=None, help="stop after this many s"
    )
    serve.add_argument(
        "--solve-budget",
        type=number_in(float, 1e-6, 10.0),
        default=None,
        help="s; a slower solve is dropped and a zero command sent (default tau; at most tau)",
    )
    serve.add_argument("--use-sim-time", action="store_true", help="the node's clock is /clock (a simulator)")
    serve.add_argument("--localhost-only", action="store_true", help="keep DDS traffic on 127.0.0.1")
    _add_ros2_arguments(serve)
    _add_transport_argument(serve)
    serve.add_argument(
        "--ros-args",
        nargs=argparse.REMAINDER,
        default=None,
        help="(last; rclpy) ROS 2's arguments: -p name:=value sets a parameter, -r __node:=name renames",
    )
    serve.set_defaults(func=cmd_serve)
    rehearse = sub.add_parser(
        "rehearse", help="drive the PyBullet Husky from a `serve` node in another process, over DDS"
    )
    rehearse.add_argument("scenario", help="a scenario YAML path or the name of a shipped scenario")
    rehearse.add_argument(
        "--controller", choices=controller_choices(), default=default_controller(on_robot=True)
    )
    rehearse.add_argument("--horizon", type=horizon_arg, default=None, help=HORIZON_HELP)
    rehearse.add_argument("--gamma", type=unit_float_arg, default=None, help="CBF decay rate in [0, 1]")
    rehearse.add_argument("--seed", type=seed_arg, default=None, help="noise and random-field seed")
    rehearse.add_argument(
        "--out", type=path_arg, default=None, help="output directory (default results/rehearse__<run>)"
    )
    rehearse.add_argument(
        "--domain-id",
        type=number_in(int, 0, MAX_DOMAIN_ID),
        default=None,
        help=f"DDS domain in [0, {MAX_DOMAIN_ID}] (default: the first free of 100 to 199 on this machine)",
    )
    rehearse.add_argument(
        "--reply-timeout", type=number_in(float, 0.01, 600.0), default=10.0,
        help="wall s to wait for each /cmd_vel before braking (counted)",
    )  # fmt: skip
    _add_transport_argument(rehearse)
    rehearse.add_argument(
        "--cmd-vel-stamped", action="store_true", help="the node publishes geometry_msgs/TwistStamped"
    )
    add_live_argument(rehearse)
    rehearse.set_defaults(func=cmd_rehearse)
