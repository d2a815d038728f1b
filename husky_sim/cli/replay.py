"""`husky-sim replay`: a real recording's commands through the simulated Husky."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import number_in, path_arg


def cmd_replay(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.realcheck.replay import run_replay
    from husky_sim.runs.run_folder import default_replay_dir

    bag = Path(args.bag)
    out = Path(args.out) if args.out else default_replay_dir(bag)
    lines = run_replay(
        bag,
        out,
        cmd_topic=args.cmd_topic,
        odom_topic=args.odom_topic,
        multiplier=args.wheel_separation_multiplier,
        ground_friction=args.ground_friction,
    )
    print("\n".join(lines))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `replay`."""
    replay = sub.add_parser(
        "replay", help="drive the simulated Husky with a recording's commands; measure the divergence"
    )
    replay.add_argument("bag", help="a ROS 1 .bag, a ROS 2 bag directory, or a CSV t,v,omega,x,y,theta")
    replay.add_argument("--cmd-topic", default="/cmd_vel", help="Twist or TwistStamped (default /cmd_vel)")
    replay.add_argument(
        "--odom-topic", default="/odometry/filtered", help="nav_msgs/Odometry (default /odometry/filtered)"
    )
    replay.add_argument(
        "--out", type=path_arg, default=None, help="output directory (default results/replay__<bag>)"
    )
    replay.add_argument(
        "--wheel-separation-multiplier",
        type=number_in(float, 0.5, 5.0),
        default=None,
        metavar="M",
        help="default 1.875",
    )
    replay.add_argument(
        "--ground-friction",
        type=number_in(float, 0.01, 5.0),
        default=None,
        metavar="MU",
        help="the tyres' friction coefficient (default: the default ground's)",
    )
    replay.set_defaults(func=cmd_replay)
