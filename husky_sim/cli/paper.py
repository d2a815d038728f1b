"""`husky-sim paper`: the paper's claims checked with runs; writes claims.md."""

from __future__ import annotations

import argparse

from husky_sim import interrupts
from husky_sim.cli.common import jobs_arg, path_arg


def cmd_paper(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.runs.run_folder import prepare_out_dir
    from husky_sim.study.claims import run_paper_report

    interrupts.begin_run()  # workers are stopped, not orphaned, on a signal
    out = prepare_out_dir(Path(args.out))
    results = run_paper_report(out, jobs=args.jobs, progress=not args.quiet)
    for r in results:
        print(f"{r.kinematic.verdict:>15s} | {r.physics.verdict:>15s} | {r.claim}")
    print(f"(kinematic | PyBullet) -> {out / 'claims.md'}")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `paper`."""
    from husky_sim.runs.run_folder import PAPER_DIR

    paper = sub.add_parser("paper", help="check the paper's claims; writes claims.md")
    paper.add_argument(
        "--out", type=path_arg, default=str(PAPER_DIR), help=f"output directory (default {PAPER_DIR})"
    )
    paper.add_argument("--jobs", type=jobs_arg, default=2, help="worker processes (default 2)")
    paper.add_argument("--quiet", action="store_true", help="no progress bar")
    paper.set_defaults(func=cmd_paper)
