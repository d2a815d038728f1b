"""`husky-sim campaign` (many layouts of scenario families with one controller: failure rates
with confidence bounds) and `husky-sim falsify` (a search for a family's worst layout)."""

from __future__ import annotations

import argparse

from husky_sim import interrupts
from husky_sim.cli.common import (
    HORIZON_HELP,
    add_backend_args,
    controller_choices,
    count_arg,
    default_controller,
    horizon_arg,
    jobs_arg,
    path_arg,
    seed_arg,
)
from husky_sim.cli.families import add_param_arg, add_robot_arg


def _jobs(args: argparse.Namespace) -> int:
    import os

    return args.jobs or os.cpu_count() or 1


def cmd_campaign(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.campaign.report import write_report
    from husky_sim.campaign.runner import CampaignSpec, plan, run_campaign

    spec = CampaignSpec(
        tuple(args.families),
        args.controller,
        args.count,
        args.seed,
        args.horizon,
        dict(args.param),
        args.robot,
    )
    out = Path(args.out)
    interrupts.begin_run()
    rows = run_campaign(
        spec, out, _jobs(args), args.backend, args.scheduler, progress=not args.quiet, log=print
    )
    report = write_report(spec, plan(spec, out), rows, out)
    reached = sum(r["class"] == "reached" for r in rows)
    print(f"{reached}/{len(rows)} reached -> {report}, {out / 'campaign.csv'}")
    return 0


def cmd_falsify(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.campaign.falsify import comparison_table, search, summarise

    interrupts.begin_run()
    methods = ["cma", "random"] if args.method == "both" else [args.method]
    rows = []
    for method in methods:
        out = Path(args.out) / method if len(methods) > 1 else Path(args.out)
        s = search(
            args.family,
            args.controller,
            args.budget,
            args.seed,
            out,
            method,
            args.horizon,
            dict(args.param),
            _jobs(args),
            args.backend,
            args.scheduler,
            log=print,
        )
        rows.append((summarise(s), out))
    table = comparison_table(args.family, args.controller, args.horizon, rows)
    (Path(args.out) / "falsify.md").write_text(table + "\n")
    print(table)
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `campaign` and `falsify`."""
    from husky_sim.families.registry import family_names

    campaign = sub.add_parser(
        "campaign", help="run K layouts of each family with one controller: failure rates with bounds"
    )
    campaign.add_argument("--families", nargs="+", choices=family_names(), required=True)
    campaign.add_argument("--controller", choices=controller_choices(), default=default_controller())
    campaign.add_argument("--count", type=count_arg, default=25, help="layouts per family (default 25)")
    campaign.add_argument("--seed", type=seed_arg, default=0, help="layout seed (default 0)")
    campaign.add_argument(
        "--horizon", type=horizon_arg, default=None, help=f"{HORIZON_HELP} (default: the layouts')"
    )
    add_param_arg(campaign)
    add_robot_arg(campaign)
    campaign.add_argument("--jobs", type=jobs_arg, default=None, help="worker processes (default: all cores)")
    add_backend_args(campaign, "runs")
    campaign.add_argument("--quiet", action="store_true", help="no progress bar")
    campaign.add_argument("--out", type=path_arg, required=True, help="the campaign's folder (resumable)")
    campaign.set_defaults(func=cmd_campaign)

    falsify = sub.add_parser("falsify", help="search a family for a controller's worst layout (CMA-ES)")
    falsify.add_argument("family", choices=family_names())
    falsify.add_argument("--controller", choices=controller_choices(), default=default_controller())
    falsify.add_argument("--budget", type=count_arg, default=30, help="runs (default 30)")
    falsify.add_argument("--seed", type=seed_arg, default=0, help="search and layout seed (default 0)")
    falsify.add_argument(
        "--method",
        choices=("cma", "random", "both"),
        default="cma",
        help="CMA-ES, random sampling, or both with the same budget (default cma)",
    )
    falsify.add_argument(
        "--horizon", type=horizon_arg, default=None, help=f"{HORIZON_HELP} (default: the layouts')"
    )
    add_param_arg(falsify)
    falsify.add_argument("--jobs", type=jobs_arg, default=None, help="worker processes (default: all cores)")
    add_backend_args(falsify, "runs")
    falsify.add_argument("--out", type=path_arg, required=True, help="output folder")
    falsify.set_defaults(func=cmd_falsify)
