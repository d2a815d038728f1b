"""`husky-sim bench`: NMPC solve times of every solver backend on the same recorded problems.

For each safety variant, horizon and obstacle count, the kinematic point-stabilisation loop is run
once with the reference backend (IPOPT) and every control step's problem (parameters and
warm-start guess) is recorded. That sequence is then replayed, in order, through each backend, so
times and answers are compared on identical problems: wall time (perf_counter) and this thread's
CPU time (thread_time) of each `solve` call. CPU time is what to compare on a shared machine, where
wall time swings about 3x.

For every backend but IPOPT, `first_control_diff_p99` is the first control's largest difference
from converged IPOPT on the same problem: IPOPT run cold from the same guess to a tolerance of
1e-10, so that a difference is the backend's, not a different warm start's (a warm-started IPOPT
can settle in another local optimum than a cold one from the same guess).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np

from controllers import SAFETY_CONSTRAINTS, NMPCConfig, NMPCController
from controllers.backends import make_solver
from controllers.backends.ipopt import IpoptSolver
from controllers.backends.opti import OptiSolver
from controllers.config import SOLVER_BACKENDS, SolverOptions
from controllers.ocp import Plan, layout_for, paper_nlp
from husky_sim.runs.paper_problems import CLUTTERED_POINT_STABILISATION, PAPER_POINT_STABILISATION
from husky_sim.sim.kinematic import KinematicProblem, run_kinematic

REFERENCE = "ipopt"
DEFAULT_SOLVER = SolverOptions().backend
#: Tolerance of the converged IPOPT the first controls are compared with.
CONVERGED_TOL = 1e-10


@dataclass(frozen=True)
class BenchRecord:
    """Solve-time statistics (ms) of one backend on one cell's recorded problems."""

    variant: str
    horizon: int
    obstacles: int
    solver: str
    default: bool  # the backend NMPCController uses unless told otherwise
    median_ms: float
    p95_ms: float
    p99_ms: float
    max_ms: float
    cpu_median_ms: float
    cpu_p99_ms: float
    steps: int
    fallbacks: int  # solves the backend did not answer itself (fatrop: IPOPT did; others: failed)
    first_control_diff_p99: float | None = None  # max |u0 - u0_ipopt|, p99 over the problems


@dataclass(frozen=True)
class RecordedProblem:
    """One control step's problem as the closed loop posed it."""

    parameters: np.ndarray
    guess: np.ndarray


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


def record_problems(config: NMPCConfig, obstacles: int, steps: int) -> list[RecordedProblem]:
    """Run the kinematic closed loop with the reference backend; each step's first problem."""
    controller = NMPCController(config.with_(solver=replace(config.solver, backend=REFERENCE)))
    problems: list[RecordedProblem] = []
    controller.on_solve = lambda p, guess: problems.append(RecordedProblem(p.copy(), guess.copy()))
    problem = problem_for(obstacles)
    run_kinematic(
        controller,
        problem.start,
        problem.reference,
        problem.obstacles,
        config.tau_s,
        steps * config.tau_s,
        problem.robot_radius_m,
    )
    return problems


def replay(config: NMPCConfig, backend: str, problems: Sequence[RecordedProblem]) -> dict[str, np.ndarray]:
    """Solve the recorded problems in order with one backend: times (s), first controls, fallbacks."""
    options = replace(config.solver, backend=backend)
    if backend == "opti":
        solver = OptiSolver(config.with_(solver=options))
    else:
        solver = make_solver(paper_nlp(config), options)
    layout = layout_for(config)
    wall, cpu, first, fallbacks = [], [], [], 0
    for problem in problems:
        w0, c0 = time.perf_counter(), time.thread_time()
        raw = solver.solve(problem.parameters, problem.guess)
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
        first.append(Plan.from_vector(raw.decision, layout).controls[0])
        fallbacks += bool(raw.fallback_reason) or not raw.success
    return {
        "wall_s": np.array(wall),
        "cpu_s": np.array(cpu),
        "first_control": np.array(first),
        "fallbacks": np.array(fallbacks),
    }


def converged_solver(config: NMPCConfig) -> IpoptSolver:
    """IPOPT on the paper's NLP of `config`, converged to CONVERGED_TOL (no acceptable exit): the
    answer other backends are compared with (call `reset` before each problem to solve it cold)."""
    options = replace(
        config.solver, backend=REFERENCE, tol=CONVERGED_TOL, acceptable_tol=CONVERGED_TOL, max_iter=3000
    )
    return make_solver(paper_nlp(config), options)


def converged_first_controls(config: NMPCConfig, problems: Sequence[RecordedProblem]) -> np.ndarray:
    """First control of each problem solved by IPOPT cold from its guess to CONVERGED_TOL."""
    solver = converged_solver(config)
    layout = layout_for(config)
    first = []
    for problem in problems:
        solver.reset()
        first.append(
            Plan.from_vector(solver.solve(problem.parameters, problem.guess).decision, layout).controls[0]
        )
    return np.array(first)


def bench_cell(
    variant: str, horizon: int, obstacles: int, solvers: Sequence[str], steps: int, gamma: float
) -> list[BenchRecord]:
    """Record one cell's problems, replay them through each solver, summarise."""
    config = NMPCConfig(safety=variant, horizon=horizon, gamma=gamma, obstacle_slots=obstacles)
    problems = record_problems(config, obstacles, steps)
    runs = {name: replay(config, name, problems) for name in solvers}
    converged = converged_first_controls(config, problems) if set(solvers) - {REFERENCE} else None
    records = []
    for name in solvers:
        run = runs[name]
        wall, cpu = 1000.0 * run["wall_s"], 1000.0 * run["cpu_s"]
        diff = None
        if name != REFERENCE and converged is not None:
            per_problem = np.max(np.abs(run["first_control"] - converged), axis=1)
            diff = float(np.percentile(per_problem, 99))
        records.append(
            BenchRecord(
                variant=variant,
                horizon=horizon,
                obstacles=obstacles,
                solver=name,
                default=name == DEFAULT_SOLVER,
                median_ms=float(np.median(wall)),
                p95_ms=float(np.percentile(wall, 95)),
                p99_ms=float(np.percentile(wall, 99)),
                max_ms=float(np.max(wall)),
                cpu_median_ms=float(np.median(cpu)),
                cpu_p99_ms=float(np.percentile(cpu, 99)),
                steps=int(wall.size),
                fallbacks=int(run["fallbacks"]),
                first_control_diff_p99=diff,
            )
        )
    return records


def run_bench(
    controllers: Sequence[str] = SAFETY_CONSTRAINTS,
    horizons: Sequence[int] = (5, 7, 12),
    obstacle_counts: Sequence[int] = (1, 7),
    solvers: Sequence[str] = SOLVER_BACKENDS,
    steps: int = 150,
    gamma: float = 0.1,
    progress: bool = False,
) -> list[BenchRecord]:
    """Every cell of controllers x horizons x obstacle counts, each on its own recorded problems.
    A record names its controller `variant` (the JSON key the bench's consumers read)."""
    records = []
    for variant in controllers:
        for horizon in horizons:
            for count in obstacle_counts:
                cell = bench_cell(variant, horizon, count, solvers, steps, gamma)
                if progress:
                    medians = ", ".join(f"{r.solver} {r.cpu_median_ms:.2f}" for r in cell)
                    print(f"  {variant} N={horizon} obstacles={count}: CPU median ms {medians}", flush=True)
                records += cell
    return records


def format_table(records: Sequence[BenchRecord]) -> str:
    """Markdown table: per cell and backend, CPU and wall times and the speed-up over IPOPT."""
    lines = [
        "| controller | N | obstacles | solver | CPU median / p99 (ms) | wall median / p95 / p99 / max (ms) "
        "| CPU speed-up vs ipopt | fallbacks | first-control diff p99 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    reference = {(r.variant, r.horizon, r.obstacles): r for r in records if r.solver == REFERENCE}
    for r in records:
        ref = reference.get((r.variant, r.horizon, r.obstacles))
        speedup = f"{ref.cpu_median_ms / r.cpu_median_ms:.1f}x" if ref and r.cpu_median_ms > 0 else "-"
        diff = "-" if r.first_control_diff_p99 is None else f"{r.first_control_diff_p99:.1e}"
        name = f"{r.solver} (default)" if r.default else r.solver
        lines.append(
            f"| {r.variant} | {r.horizon} | {r.obstacles} | {name} "
            f"| {r.cpu_median_ms:.2f} / {r.cpu_p99_ms:.2f} "
            f"| {r.median_ms:.2f} / {r.p95_ms:.2f} / {r.p99_ms:.2f} / {r.max_ms:.2f} "
            f"| {speedup} | {r.fallbacks} | {diff} |"
        )
    return "\n".join(lines)


def records_json(records: Sequence[BenchRecord]) -> str:
    return json.dumps([asdict(r) for r in records], indent=2)
