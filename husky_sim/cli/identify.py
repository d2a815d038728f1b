"""`husky-sim identify`: the simulated Husky's yaw-rate lag from step commands."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import UsageError, path_arg
from husky_sim.paths import DEFAULT_ROBOT


def cmd_identify(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.sim.robot_description import load_robot
    from husky_sim.sim.yaw_response import PAYLOAD_FRACTIONS, identify_by_payload, write_identification

    robot = load_robot(args.robot)
    most = robot.specs.spec_sheet.max_payload_kg
    identifications = identify_by_payload([most * f for f in PAYLOAD_FRACTIONS], robot.name)
    for identification in identifications:
        print("\n".join(identification.lines()))
    out = Path(args.out) if args.out else robot.yaw_response_file
    command = "husky-sim identify" + ("" if robot.name == DEFAULT_ROBOT else f" --robot {robot.name}")
    command += "" if args.out is None else f" --out {args.out}"
    try:
        write_identification(identifications, out, command, robot.title)
    except OSError as exc:
        raise UsageError(f"identify: cannot write {out} ({exc.strerror or exc})") from None
    print(f"-> {out}")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `identify`."""
    identify = sub.add_parser(
        "identify", help="fit the simulated Husky's yaw-rate lag (gain, time constant) to step commands"
    )
    identify.add_argument(
        "--out",
        type=path_arg,
        default=None,
        help="YAML file to write (default: the robot folder's yaw_response.yaml, the scenarios' default)",
    )
    identify.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"the robot's folder under assets/ (default {DEFAULT_ROBOT})"
    )
    identify.set_defaults(func=cmd_identify)
