"""`husky-sim bench`: closed-loop NMPC solve times, ours (nlpsol built once) against the naive
casadi.Opti baseline, for each safety variant, horizon and obstacle count, in one run.

Each cell runs the kinematic point-stabilisation loop for a fixed number of control steps and
records the wall time of every `solve` call (parameter packing, warm start and IPOPT included).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from controllers import SAFETY_CONSTRAINTS, NMPCConfig, NMPCController
from husky_sim.kinematic import run_kinematic
from husky_sim.scenarios_kinematic import (
    CLUTTERED_POINT_STABILISATION,
    PAPER_POINT_STABILISATION,
    KinematicProblem,
)

SOLVERS = ("nlpsol", "opti")


@dataclass(frozen=True)
class BenchRecord:
    """Solve-time statistics (ms) of one closed-loop cell."""

    variant: str
    horizon: int
    obstacles: int
    solver: str
    median_ms: float
    p95_ms: float
    max_ms: float
    steps: int
    fallbacks: int


def problem_for(obstacles: int) -> KinematicProblem:
    """1 obstacle: the paper's problem; more: the cluttered variant truncated to that count."""
    base = PAPER_POINT_STABILISATION if obstacles <= 1 else CLUTTERED_POINT_STABILISATION
    if obstacles > len(base.obstacles):
        raise ValueError(f"obstacles: must be in [1, {len(base.obstacles)}], got {obstacles}")
    return KinematicProblem(
        base.name,
        base.start,
        base.reference,
        base.obstacles[:obstacles],
        base.robot_radius_m,
        base.duration_s,
    )


def bench_cell(
    variant: str, horizon: int, obstacles: int, solver: str, steps: int, gamma: float
) -> BenchRecord:
    """Run one closed loop of `steps` control steps and summarise its solve times."""
    problem = problem_for(obstacles)
    config = NMPCConfig(safety=variant, horizon=horizon, gamma=gamma, obstacle_slots=obstacles)
    controller = NMPCController(config, backend=solver)
    episode = run_kinematic(
        controller,
        problem.start,
        problem.reference,
        problem.obstacles,
        config.tau_s,
        steps * config.tau_s,
        problem.robot_radius_m,
    )
    ms = 1000.0 * episode.solve_time_s
    return BenchRecord(
        variant,
        horizon,
        obstacles,
        solver,
        float(np.median(ms)),
        float(np.percentile(ms, 95)),
        float(np.max(ms)),
        int(ms.size),
        episode.fallbacks,
    )


def run_bench(
    variants: Sequence[str] = SAFETY_CONSTRAINTS,
    horizons: Sequence[int] = (5, 7, 12),
    obstacle_counts: Sequence[int] = (1, 7),
    solvers: Sequence[str] = SOLVERS,
    steps: int = 150,
    gamma: float = 0.1,
    progress: bool = False,
) -> list[BenchRecord]:
    records = []
    for variant in variants:
        for horizon in horizons:
            for count in obstacle_counts:
                for solver in solvers:
                    rec = bench_cell(variant, horizon, count, solver, steps, gamma)
                    if progress:
                        print(
                            f"  {variant} N={horizon} obstacles={count} {solver}: "
                            f"median {rec.median_ms:.2f} ms",
                            flush=True,
                        )
                    records.append(rec)
    return records


def format_table(records: Sequence[BenchRecord]) -> str:
    """Markdown table with the Opti/nlpsol median ratio per cell."""
    by_key = {(r.variant, r.horizon, r.obstacles, r.solver): r for r in records}
    lines = [
        "| variant | N | obstacles | ours median / p95 / max (ms) | opti median / p95 / max (ms) "
        "| opti/ours median | fallbacks ours/opti |",
        "|---|---|---|---|---|---|---|",
    ]
    seen = []
    for r in records:
        key = (r.variant, r.horizon, r.obstacles)
        if key in seen:
            continue
        seen.append(key)
        ours, opti = by_key.get((*key, "nlpsol")), by_key.get((*key, "opti"))

        def cell(x: BenchRecord | None) -> str:
            return "-" if x is None else f"{x.median_ms:.2f} / {x.p95_ms:.2f} / {x.max_ms:.2f}"

        ratio = f"{opti.median_ms / ours.median_ms:.1f}x" if ours and opti else "-"
        fb = f"{ours.fallbacks if ours else '-'} / {opti.fallbacks if opti else '-'}"
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {cell(ours)} | {cell(opti)} | {ratio} | {fb} |")
    return "\n".join(lines)


def records_json(records: Sequence[BenchRecord]) -> str:
    return json.dumps([asdict(r) for r in records], indent=2)
