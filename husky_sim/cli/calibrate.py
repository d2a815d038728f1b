"""`husky-sim calibrate` (fit a ground to a real recording) and `husky-sim drive-response` (how the
simulated Husky answers held commands on a ground)."""

from __future__ import annotations

import argparse
import json

from husky_sim.cli.common import UsageError, number_in, path_arg


def _command_pair(text: str) -> tuple[float, float]:
    """An argparse type: V,W (m/s, rad/s), |V| <= 5, |W| <= 10."""
    parts = text.split(",")
    try:
        v, w = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected V,W (m/s, rad/s), got {text[:40]!r}") from None
    if not (abs(v) <= 5.0 and abs(w) <= 10.0):
        raise argparse.ArgumentTypeError(f"expected |V| <= 5 m/s and |W| <= 10 rad/s, got {text[:40]!r}")
    return v, w


def _load_recording(path: str, cmd_topic: str, odom_topic: str):
    """A DRIVE recording CSV, or commands and odometry (a ROS 1/2 bag, or a replay CSV t, v, omega,
    x, y, theta) read by the replay's readers."""
    from pathlib import Path

    from husky_sim.calibration.recordings import (
        RecordingError,
        drive_recording_from_commands,
        load_drive_recording,
    )
    from husky_sim.realcheck.replay import load_recording
    from husky_sim.sim.drive import DriveConfig

    if Path(path).suffix.lower() == ".csv":
        try:
            return load_drive_recording(Path(path))
        except RecordingError as exc:
            if "unknown header" not in str(exc):
                raise
    replayed = load_recording(Path(path), cmd_topic, odom_topic)
    multiplier = DriveConfig().wheel_separation_multiplier
    return drive_recording_from_commands(
        path, replayed.cmd_t_s, replayed.commands, replayed.pose_t_s, replayed.poses, multiplier
    )


def cmd_calibrate(args: argparse.Namespace) -> int:
    import shlex
    from pathlib import Path

    from husky_sim.calibration.fit import fit_ground, write_calibration
    from husky_sim.sim.ground import DEFAULT_GROUND, Ground, load_ground

    recording = _load_recording(args.recording, args.cmd_topic, args.odom_topic)
    if args.base is not None:
        base = load_ground(args.base)
    else:  # without wheel speeds the drive's response cannot be fitted: keep the default ground's
        base = Ground() if recording.wheel_step_times else load_ground(DEFAULT_GROUND)
    name = args.name or recording.name
    print(f"{recording.path}: {len(recording.steps)} steady steps; fitting ground {name!r}")
    calibration = fit_ground(recording, base, name)
    words = ["husky-sim", "calibrate", args.recording, "--out", args.out]
    words += ["--name", args.name] if args.name else []
    words += ["--base", args.base] if args.base else []
    command = " ".join(shlex.quote(w) for w in words)
    try:
        written = write_calibration(calibration, Path(args.out), command)
    except OSError as exc:
        raise UsageError(f"calibrate: cannot write {args.out} ({exc.strerror or exc})") from None
    for path in written:
        print(f"-> {path}")
    return 0


def cmd_drive_response(args: argparse.Namespace) -> int:
    from husky_sim.calibration.drive_response import drive_response, format_table
    from husky_sim.sim.ground import load_ground

    ground = load_ground(args.ground)
    rows = drive_response(ground, list(args.commands), payload_kg=args.payload_kg)
    if args.json:
        print(json.dumps([r.as_dict() for r in rows], indent=2))
    else:
        print("\n".join(format_table(rows, ground.name, args.payload_kg)))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `calibrate` and `drive-response`."""
    cal = sub.add_parser(
        "calibrate", help="fit a ground (tyre contact and drive response) to a real Husky drive recording"
    )
    cal.add_argument(
        "recording",
        help="a DRIVE recording CSV (wet-grass raw log or tile windows), or a ROS 1 .bag / ROS 2 bag "
        "directory / CSV t,v,omega,x,y,theta of commands and odometry (its wheels taken to follow them)",
    )
    cal.add_argument("--cmd-topic", default="/cmd_vel", help="bags: Twist or TwistStamped (default /cmd_vel)")
    cal.add_argument(
        "--odom-topic",
        default="/odometry/filtered",
        help="bags: nav_msgs/Odometry (default /odometry/filtered)",
    )
    cal.add_argument("--out", type=path_arg, required=True, help="folder for ground.yaml and calibration.md")
    cal.add_argument("--name", default=None, help="the ground's name (default: the recording's)")
    cal.add_argument(
        "--base",
        default=None,
        help="ground whose unfitted parameters are kept, where the fit starts (default: the tyre's defaults; "
        "for a recording without wheel speeds the default ground, whose drive response is kept)",
    )
    cal.set_defaults(func=cmd_calibrate)

    resp = sub.add_parser(
        "drive-response", help="hold commands from rest on a ground; print the simulated Husky's answer"
    )
    resp.add_argument(
        "--ground",
        default=None,
        help="a shipped ground's name or a ground file (default: the default ground)",
    )
    resp.add_argument(
        "--payload-kg", type=number_in(float, 0.0, 200.0), default=0.0, metavar="KG", help="payload (kg)"
    )
    resp.add_argument(
        "--commands",
        type=_command_pair,
        nargs="+",
        required=True,
        metavar="V,W",
        help="commands (m/s, rad/s)",
    )
    resp.add_argument("--json", action="store_true", help="print a JSON list of rows")
    resp.set_defaults(func=cmd_drive_response)
