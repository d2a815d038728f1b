"""Run a matrix of scenario runs (scenario x controller x horizon x gamma) in parallel.

Each cell is one `run_scenario` call in its own worker process (PyBullet clients and compiled
solvers are per process), written to `OUT/runs/<cell>/`. The suite writes `OUT/results.csv` (one
row per cell: the summary keys plus `run_dir`) and `OUT/results.md` (a Markdown table), and the
cells come back in matrix order whatever order the workers finish in, so the files are
deterministic except for the wall-clock columns.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from tqdm import tqdm

from controllers import registry
from controllers.husky_cbf.registration import HUSKY_CBF
from controllers.paper import BT, CBF, RELAX_CBF
from husky_sim.runs.parallel import Backend, parallel_map, process_map
from husky_sim.runs.run_folder import RESULTS_FILE, write_results_csv

#: Columns of results.md (results.csv has every summary key).
TABLE_COLUMNS = (
    "scenario",
    "model",
    "controller",
    "horizon",
    "gamma",
    "prediction_time_s",
    "outcome",
    "min_clearance_m",
    "final_position_error_m",
    "tracking_rmse_m",
    "time_to_goal_s",
    "safety_active_steps",
    "reversals",
    "fallbacks",
    "solve_ms_median",
)


@dataclass(frozen=True)
class Cell:
    """One run of the matrix; gamma None or horizon None take the scenario file's value."""

    scenario: str  # shipped name or YAML path
    controller: str
    horizon: int | None = None
    gamma: float | None = None
    seed: int | None = None
    model: str = "physics"  # "physics" (PyBullet) or "kinematic" (the controller's unicycle)
    robot_radius_m: float | None = None  # kinematic only: override the scenario's robot circle
    solver: str | None = None  # NLP backend; None: the scenario file's (default SolverOptions')

    def label(self) -> str:
        parts = [Path(self.scenario).stem, self.controller]
        if self.model != "physics":
            parts.insert(1, self.model)
        if self.horizon is not None:
            parts.append(f"N{self.horizon}")
        if self.gamma is not None:
            parts.append(f"g{self.gamma:g}")
        if self.seed is not None:
            parts.append(f"s{self.seed}")
        if self.solver is not None:
            parts.append(self.solver)
        return "__".join(parts)


def matrix(
    scenarios: Sequence[str],
    controllers: Sequence[str],
    horizons: Sequence[int | None] = (None,),
    gammas: Sequence[float | None] = (None,),
    seed: int | None = None,
    solver: str | None = None,
) -> list[Cell]:
    """Every combination, in a fixed order (scenario, controller, gamma, horizon), each once, on
    the NLP backend `solver` (None: each scenario file's)."""
    cells = [
        Cell(s, c, n, g, seed, solver=solver)
        for s in scenarios
        for c in controllers
        for g in (gammas if registry.entry(c).decay_rate else gammas[:1])  # bt has no gamma
        for n in horizons
    ]
    return list(dict.fromkeys(cells))


#: The scenario suite's horizons (the issue's N in {5, 7, 12}).
SUITE_HORIZONS = (5, 7, 12)
#: The paper's three (controllers.paper), the suite's default controllers.
SUITE_CONTROLLERS = registry.paper_names(with_baseline=False)
#: Our controller (controllers/husky_cbf), reported beside the paper's three.
OURS = HUSKY_CBF.name
_BT, _CBF, _RELAX = BT.name, CBF.name, RELAX_CBF.name

#: The gamma values the paper uses beyond each scenario file's own: gamma = 0.05 in point
#: stabilisation ("too low for plain CBF, Relax-CBF still reaches"); in tracking, Relax-CBF
#: gamma = 0.2 at N = 12 and CBF / Relax-CBF gamma = 0.03 at N = 5 (Fig. 4 (b) and (d)).
PAPER_GAMMA_CELLS = tuple(
    [Cell("paper_point_stabilisation", c, n, 0.05) for c in (_CBF, _RELAX) for n in SUITE_HORIZONS]
    + [
        cell
        for s in ("paper_dynamic_tracking", "paper_dynamic_tracking_crossing")
        for cell in (Cell(s, _RELAX, 12, 0.2), Cell(s, _CBF, 5, 0.03), Cell(s, _RELAX, 5, 0.03))
    ]
)


def standard_matrix(scenarios: Sequence[str]) -> list[Cell]:
    """The suite: every scenario x bt/cbf/relax-cbf x N in {5, 7, 12} at the file's gamma, plus
    the paper's own gamma values on the paper's scenarios."""
    cells = matrix(scenarios, SUITE_CONTROLLERS, SUITE_HORIZONS)
    return cells + [c for c in PAPER_GAMMA_CELLS if c.scenario in scenarios]


def run_cell(cell: Cell, out_dir: Path | None) -> dict[str, object]:
    """Run one cell (in a worker); a crash becomes an `error` row instead of killing the suite.
    Kinematic cells write nothing and return their per-step series in the summary."""
    from husky_sim.runs.run import run_scenario, run_scenario_kinematic

    run_dir = out_dir / "runs" / cell.label() if out_dir is not None and cell.model == "physics" else None
    try:
        if cell.model == "kinematic":
            summary = run_scenario_kinematic(
                cell.scenario, cell.controller, cell.horizon, cell.gamma, cell.robot_radius_m
            ).as_dict()
        else:
            summary = run_scenario(
                cell.scenario,
                cell.controller,
                cell.horizon,
                cell.gamma,
                cell.seed,
                run_dir,
                solver=cell.solver,
            ).as_dict()
    except Exception as exc:  # noqa: BLE001 - reported per cell, the suite goes on
        return _error_row(cell, exc, out_dir)
    summary["run_dir"] = str(Path("runs") / cell.label()) if run_dir is not None else ""
    return summary


def _error_row(cell: Cell, exc: BaseException, out_dir: Path | None) -> dict[str, object]:
    return {
        "scenario": Path(cell.scenario).stem,
        "model": cell.model,
        "controller": cell.controller,
        "horizon": cell.horizon,
        "gamma": cell.gamma,
        "outcome": "error",
        "error": f"{type(exc).__name__}: {exc}",
        "traceback": traceback.format_exc(limit=3),
        "run_dir": "" if out_dir is None or cell.model != "physics" else str(Path("runs") / cell.label()),
    }


def run_suite(
    cells: Sequence[Cell],
    jobs: int = 2,
    out_dir: Path | None = None,
    progress: bool = True,
    on_result: Callable[[Cell, dict[str, object]], None] | None = None,
    backend: Backend = "local",
    scheduler: str | None = None,
) -> list[dict[str, object]]:
    """Run the cells on `jobs` worker processes (husky_sim.runs.parallel: local, or a Dask cluster
    at `scheduler` whose workers see out_dir); return their summaries in `cells` order."""
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    bar = tqdm(total=len(cells), disable=not progress, unit="run", dynamic_ncols=True)
    rows: list[dict[str, object]] = [{}] * len(cells)

    def done(i: int, summary: dict[str, object] | BaseException) -> None:
        if isinstance(summary, BaseException):  # a dead worker (crash, out of memory)
            summary = _error_row(cells[i], summary, out_dir)
        rows[i] = _finish(cells[i], summary, bar, on_result)

    try:
        parallel_map(partial(run_cell, out_dir=out_dir), cells, jobs, done, backend, scheduler)
    finally:
        bar.close()
    if out_dir is not None:
        write_results(rows, out_dir)
    return rows


def write_figures(
    rows: Sequence[dict[str, object]], out_dir: Path, per_run: bool = False, jobs: int = 1
) -> list[Path]:
    """One comparison figure per scenario (all its PyBullet runs overlaid), the gamma x N tuning
    maps, and with `per_run` every run's own figures (in its run directory's `plots/`); drawn
    scenario by scenario on `jobs` processes (matplotlib drew the 72-run suite's figures in 16 s
    of CPU, a fifth of the suite's wall time when done in one process after the runs)."""
    done = [r for r in rows if r.get("run_dir") and r["outcome"] != "error"]
    if not done:
        return []
    run_dirs: dict[str, list[Path]] = {str(r["scenario"]): [] for r in rows}
    for r in done:
        run_dirs[str(r["scenario"])].append(out_dir / str(r["run_dir"]))
    tasks = [(scenario, dirs, out_dir, per_run) for scenario, dirs in run_dirs.items()]
    written: list[Path] = []
    for result in process_map(_scenario_figures, tasks, jobs):
        if isinstance(result, BaseException):
            raise result
        written += result
    return written


def _scenario_figures(task: tuple[str, list[Path], Path, bool]) -> list[Path]:
    """One scenario's figures (write_figures): its comparison if it has runs, its tuning maps from
    results.csv (error rows included), and with `per_run` each run's own."""
    from husky_sim.viz.comparison_figures import plot_comparison
    from husky_sim.viz.run_figures import plot_run
    from husky_sim.viz.tuning_maps import plot_tuning_maps

    scenario, run_dirs, out_dir, per_run = task
    plots = out_dir / "plots"
    written = [plot_comparison(run_dirs, plots / f"comparison_{scenario}")[0]] if run_dirs else []
    written += [png for png, _ in plot_tuning_maps(out_dir / RESULTS_FILE, plots, scenario).values()]
    if per_run:
        for run_dir in run_dirs:
            written += [png for png, _ in plot_run(run_dir, run_dir / "plots").values()]
    return written


def _finish(
    cell: Cell,
    summary: dict[str, object],
    bar: tqdm,
    on_result: Callable[[Cell, dict[str, object]], None] | None,
) -> dict[str, object]:
    bar.set_postfix_str(f"{cell.label()}: {summary['outcome']}", refresh=False)
    bar.update()
    if on_result is not None:
        on_result(cell, summary)
    return summary


def write_results(rows: Sequence[dict[str, object]], out_dir: Path) -> tuple[Path, Path]:
    """Write results.csv (every key) and results.md (TABLE_COLUMNS)."""
    csv_path, md_path = write_results_csv(rows, out_dir), out_dir / "results.md"
    md_path.write_text(f"{markdown_table(rows)}\n{outcome_legend(rows)}")
    return csv_path, md_path


#: Why the paper's controllers deadlock on a Husky, said once for every results.md that has them.
PAPER_DEADLOCK_NOTE = (
    "`bt`, `cbf` and `relax-cbf` are the paper's controllers, reproduced unchanged, and three things "
    "make them deadlock on a Husky. (1) The robot is one circle of 0.82 m: the Husky's real footprint "
    "(0.57 m) plus a 0.25 m margin, so an obstacle near the straight line blocks a wide corridor. "
    "(2) Their model is a kinematic unicycle that knows neither the Husky's braking (3 m/s^2) nor its "
    "slow skid-steer yaw response; the margin must cover both, which is why it is that large. "
    "(3) With an obstacle on the straight line to the goal, the short-horizon plan that lowers the "
    "paper's stage cost most is to stop at the edge of the inflated circle: going round it costs more "
    "within N steps than waiting, and Relax-CBF drives s_h to 0, which leaves only B >= 0. So most "
    "short-horizon runs end `stuck` in front of the obstacle; this is the measured result of the "
    "reproduction (docs/paper_claims.md), not a fault of the simulator."
)

#: Why the paper's BT and Relax-CBF collide with a mover that comes at the Husky.
PAPER_COLLISION_NOTE = (
    "Against a mover that comes at the robot, BT and Relax-CBF (s_h -> 0, so only B >= 0) plan to "
    "the very edge of the mover's circle; their unicycle model changes speed at once, but the Husky "
    "accelerates at most 3 m/s^2 and turns slowly, so it cannot get out of the way in time and the "
    "mover touches it."
)

#: What husky-cbf changes, against the three reasons above.
OURS_NOTE = (
    f"`{OURS}` is our controller (controllers/husky_cbf), not the paper's: the same Relax-CBF "
    "NMPC-CLF, changed where the reasons above lie. It plans with the drive's acceleration limits and "
    "the identified skid-steer yaw-rate lag, so it knows how the Husky brakes and turns; it covers "
    "the body with three 0.38 m discs (plus a 0.1 m margin) instead of one 0.82 m circle; and when "
    "the straight way to the goal is blocked it follows a guidance waypoint, taken from a shortest "
    "path on a cost grid around the obstacles, instead of the goal, so that driving round the "
    "obstacle is what its short-horizon cost prefers."
)


#: A stuck run this close to its goal (m) settled beside it rather than in front of an obstacle.
NEAR_GOAL_M = 1.0
BESIDE_GOAL_NOTE = (
    "The paper's cost has no terminal term, and a unicycle beside its goal lowers a quadratic cost "
    "only by backing up and turning, which pays within a short horizon only when the lateral error "
    "is large: so it stops a few tenths of a metre beside the goal."
)


def _float_or_inf(value: object) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("inf")


def outcome_legend(rows: Sequence[dict[str, object]]) -> str:
    """What the outcome words in these rows mean, the outcomes per controller, why the paper's
    controllers deadlock (and collide with movers) on a Husky, and what husky-cbf changes."""
    from husky_sim.sim.metrics import OUTCOME_MEANINGS

    seen = {r.get("outcome") for r in rows}
    lines = ["## What the outcomes mean", ""]
    lines += [f"- `{o}`: {meaning}" for o, meaning in OUTCOME_MEANINGS.items() if o in seen]
    lines += ["", "Outcomes per controller:", ""]
    for controller in dict.fromkeys(str(r.get("controller")) for r in rows):
        outcomes = [str(r.get("outcome")) for r in rows if str(r.get("controller")) == controller]
        counts = ", ".join(f"{outcomes.count(o)} `{o}`" for o in dict.fromkeys(outcomes))
        lines.append(f"- `{controller}`: {counts} (of {len(outcomes)})")
    stuck_paper = [
        r for r in rows if r.get("outcome") == "stuck" and r.get("controller") in SUITE_CONTROLLERS
    ]
    if stuck_paper:
        lines += ["", f"{len(stuck_paper)} of {len(rows)} runs are `stuck`. {PAPER_DEADLOCK_NOTE}"]
        near = [r for r in stuck_paper if _float_or_inf(r.get("final_position_error_m")) < NEAR_GOAL_M]
        if near:
            lines += [
                "",
                f"{len(near)} of the stuck runs got past the obstacles and stopped within "
                f"{NEAR_GOAL_M:g} m of the goal, beside it. {BESIDE_GOAL_NOTE}",
            ]
    collided_paper = [
        r for r in rows if r.get("outcome") == "collided" and r.get("controller") in (_BT, _RELAX)
    ]
    if collided_paper:
        lines += ["", f"{len(collided_paper)} runs of BT or Relax-CBF are `collided`. {PAPER_COLLISION_NOTE}"]
    if any(r.get("controller") == OURS for r in rows):
        lines += ["", OURS_NOTE]
    return "\n".join(lines) + "\n"


def markdown_table(rows: Iterable[dict[str, object]], columns: Sequence[str] = TABLE_COLUMNS) -> str:
    """A Markdown table of the given columns; floats to 3 decimals, missing values as '-'."""
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in rows:
        lines.append("| " + " | ".join(_cell_text(row.get(c)) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def _cell_text(value: object) -> str:
    if value is None or value == "":
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}" if abs(value) < 1e4 else f"{value:.3g}"
    return str(value)
