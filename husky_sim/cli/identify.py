"""`husky-sim identify`: the simulated Husky's yaw-rate lag from step commands."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import UsageError, path_arg


def cmd_identify(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.sim.yaw_response import DEFAULT_FILE, identify_in_simulation, write_identification

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


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `identify`."""
    identify = sub.add_parser(
        "identify", help="fit the simulated Husky's yaw-rate lag (gain, time constant) to step commands"
    )
    identify.add_argument(
        "--out",
        type=path_arg,
        default=None,
        help="YAML file to write (default assets/husky_a200/yaw_response.yaml, the scenarios' default)",
    )
    identify.set_defaults(func=cmd_identify)
