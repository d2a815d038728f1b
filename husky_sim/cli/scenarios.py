"""`husky-sim scenarios`: list the shipped scenarios."""

from __future__ import annotations

import argparse


def cmd_scenarios(args: argparse.Namespace) -> int:
    from husky_sim.runs.scenario import load_scenario, shipped_scenarios

    for path in shipped_scenarios():
        sc = load_scenario(str(path))
        print(f"{sc.name:34s} {sc.description}")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `scenarios`."""
    scenarios = sub.add_parser("scenarios", help="list the shipped scenarios")
    scenarios.set_defaults(func=cmd_scenarios)
