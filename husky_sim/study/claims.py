"""The paper-claims report: each claim of the paper checked with runs, kinematic and in PyBullet.

`husky-sim paper --out DIR` runs the cells below (in parallel, through husky_sim.study.suite), then
judges every claim twice: on the controller's own unicycle model (the paper's MATLAB setting, with
the paper's 0.25 m robot circle on the paper's simulated scenarios) and on the Husky in PyBullet
(URDF footprint plus the scenario's margin). Each verdict is `reproduced`, `partly` or
`not reproduced`, with the numbers it rests on, in `DIR/claims.md` (and `DIR/claims.json`).
Rows that start "Ours:" report our controller `husky-cbf` (controllers/husky_cbf) on the paper's
problems against the paper's figures; it models the Husky's drive, so it runs in PyBullet only and
its kinematic verdict is `not applicable`.

Definitions used by the verdicts (the paper gives none):
- a run *succeeds* when it converges (goal held / tracking RMSE under the scenario's bound) and
  never collides;
- *deviation onset* in tracking: the first time after the robot first comes within 0.1 m of the
  reference that its error exceeds 0.2 m (s); earlier means the avoidance starts earlier;
- *smoothness*: RMS of the commanded input's change per second, dv/dt (m/s^2) and d(omega)/dt
  (rad/s^2); lower is smoother;
- *stopped time*: control steps with |v| < 0.05 m/s while more than 0.2 m off the reference (s).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from controllers import paper, registry
from husky_sim.runs.paper_problems import PAPER_ROBOT_RADIUS_M
from husky_sim.runs.run_folder import read_log
from husky_sim.study.suite import OURS, Cell, run_suite

MODELS = ("kinematic", "physics")
POINT = "paper_point_stabilisation"
TRACKING = ("paper_dynamic_tracking", "paper_dynamic_tracking_crossing")
HUSKY = ("husky_point_stabilisation", "husky_circle_tracking")
SIM_SCAN_HORIZONS = (3, 4, 5, 6, 7, 8, 10, 12)  # tau = 0.1 s: 0.3 to 1.2 s
HUSKY_SCAN_HORIZONS = (3, 4, 5, 6, 7, 8, 10, 12, 15)  # tau = 0.2 s: 0.6 to 3.0 s
BT, CBF, RELAX = paper.BT.name, paper.CBF.name, paper.RELAX_CBF.name
CONTROLLERS = registry.paper_names(with_baseline=False)
#: Our controller (suite.OURS) has PyBullet runs only: run_scenario_kinematic runs only the paper's
#: unicycle controllers.
OURS_MODELS = ("physics",)
REPRODUCED, PARTLY, NOT_REPRODUCED = "reproduced", "partly", "not reproduced"
NOT_APPLICABLE = "not applicable"  # a model the claim's controller does not run on
VERDICTS = (REPRODUCED, PARTLY, NOT_REPRODUCED, NOT_APPLICABLE)


@dataclass(frozen=True)
class PredictionTimeProblem:
    """A problem of the paper's prediction-time comparison (Sec. IV-C): its scenarios, the scanned
    horizons N and the paper's shortest N tau (s) for BT and Relax-CBF."""

    name: str
    scenarios: tuple[str, ...]
    horizons: tuple[int, ...]
    paper_s: tuple[float, float]  # (BT, Relax-CBF) N tau in s


PREDICTION_TIME_PROBLEMS = (
    PredictionTimeProblem(
        "simulation (point stabilisation, tau = 0.1 s)", (POINT,), SIM_SCAN_HORIZONS, (1.2, 0.5)
    ),
    PredictionTimeProblem(
        "Husky problems (point + circle, tau = 0.2 s)", HUSKY, HUSKY_SCAN_HORIZONS, (3.0, 1.4)
    ),
)


@dataclass(frozen=True)
class Verdict:
    verdict: str
    evidence: str


@dataclass(frozen=True)
class ClaimResult:
    claim: str
    paper: str  # where the paper says it
    kinematic: Verdict
    physics: Verdict


def _cell(model: str, scenario: str, controller: str, horizon: int, gamma: float | None = None) -> Cell:
    radius = PAPER_ROBOT_RADIUS_M if model == "kinematic" and scenario.startswith("paper_") else None
    return Cell(scenario, controller, horizon, None if controller == BT else gamma, None, model, radius)


def required_cells(model: str) -> list[Cell]:
    """Every run the report needs for one model, without duplicates, in a fixed order."""
    cells = [_cell(model, POINT, c, n, g) for c in CONTROLLERS for n in SIM_SCAN_HORIZONS for g in (None,)]
    cells += [_cell(model, POINT, c, 5, 0.05) for c in (CBF, RELAX)]
    for s in TRACKING:
        cells += [
            _cell(model, s, BT, 12),
            _cell(model, s, RELAX, 12, 0.2),
            _cell(model, s, BT, 5),
            _cell(model, s, RELAX, 5, 0.12),
            _cell(model, s, CBF, 5, 0.03),
            _cell(model, s, RELAX, 5, 0.03),
        ]
    cells += [_cell(model, s, c, n) for s in HUSKY for c in CONTROLLERS for n in HUSKY_SCAN_HORIZONS]
    if model in OURS_MODELS:
        cells += [
            _cell(model, s, OURS, n)
            for p in PREDICTION_TIME_PROBLEMS
            for s in p.scenarios
            for n in p.horizons
        ]
    return list(dict.fromkeys(cells))


class Runs:
    """Summaries of the finished cells, looked up by what a claim asks for."""

    def __init__(self, cells: Sequence[Cell], rows: Sequence[dict[str, object]], out_dir: Path) -> None:
        self._by_cell = dict(zip(cells, rows, strict=True))
        self._out_dir = out_dir

    def get(self, model: str, scenario: str, controller: str, horizon: int, gamma: float | None = None):
        return self._by_cell[_cell(model, scenario, controller, horizon, gamma)]

    def all(self) -> list[dict[str, object]]:
        return list(self._by_cell.values())

    def series(self, row: dict[str, object]) -> dict[str, np.ndarray]:
        """Per-step t_s, x_m, y_m, ref_x_m, ref_y_m, v_cmd_mps, omega_cmd_radps of a run."""
        keys = ("t_s", "x_m", "y_m", "ref_x_m", "ref_y_m", "v_cmd_mps", "omega_cmd_radps")
        if "t_s" in row:  # kinematic rows carry their series
            return {k: np.asarray(row[k], dtype=float) for k in keys}
        log = read_log(self._out_dir / str(row["run_dir"]))
        return {k: log[k] for k in keys}


def succeeded(row: dict[str, object]) -> bool:
    return bool(row["converged"]) and not bool(row["collided"])


def describe(row: dict[str, object]) -> str:
    """A short run description: controller, N, gamma, outcome and key numbers."""
    name = f"{row['controller']} N={row['horizon']}" + (
        "" if row["controller"] == BT else f" g={row['gamma']:g}"
    )
    clear = row.get("min_clearance_m")
    parts = [str(row["outcome"])]
    if clear is not None:
        parts.append(f"clearance {clear:.3f} m")
    if row.get("tracking_rmse_m") is not None:
        parts.append(f"RMSE {row['tracking_rmse_m']:.2f} m")
    elif row["outcome"] != "reached":
        parts.append(f"ended {row['final_position_error_m']:.2f} m from the goal or reference")
    if row.get("reversals"):
        parts.append(f"{row['reversals']} reversal(s)")
    return f"{name}: {', '.join(parts)}"


def deviation_onset_s(s: dict[str, np.ndarray], near_m: float = 0.1, far_m: float = 0.2) -> float | None:
    err = np.hypot(s["x_m"] - s["ref_x_m"], s["y_m"] - s["ref_y_m"])
    near = np.flatnonzero(err < near_m)
    if near.size == 0:
        return None
    after = np.flatnonzero(err[near[0] :] > far_m)
    return float(s["t_s"][near[0] + after[0]]) if after.size else None


def input_roughness(s: dict[str, np.ndarray]) -> tuple[float, float]:
    """RMS of dv/dt (m/s^2) and d(omega)/dt (rad/s^2) of the commands."""
    dt = float(np.median(np.diff(s["t_s"]))) if len(s["t_s"]) > 1 else 1.0
    dv, dw = np.diff(s["v_cmd_mps"]) / dt, np.diff(s["omega_cmd_radps"]) / dt
    return _rms(dv), _rms(dw)


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else 0.0


def stopped_time_s(s: dict[str, np.ndarray]) -> float:
    err = np.hypot(s["x_m"] - s["ref_x_m"], s["y_m"] - s["ref_y_m"])
    dt = float(np.median(np.diff(s["t_s"]))) if len(s["t_s"]) > 1 else 0.0
    return float(np.sum((np.abs(s["v_cmd_mps"]) < 0.05) & (err > 0.2)) * dt)


def _grade(checks: Sequence[bool]) -> str:
    """All hold: reproduced; some: partly; none: not reproduced (for claims of equal parts)."""
    return REPRODUCED if all(checks) else (PARTLY if any(checks) else NOT_REPRODUCED)


def _grade_primary(primary: Sequence[bool], secondary: Sequence[bool]) -> str:
    """For a claim with a main part (what the proposed method achieves) and a contrast: partly
    only when the main part holds; a contrast alone (e.g. BT struggling) reproduces nothing."""
    if not all(primary):
        return NOT_REPRODUCED
    return REPRODUCED if all(secondary) else PARTLY


def claim_long_horizon(runs: Runs, model: str) -> Verdict:
    bt, cbf, relax = (runs.get(model, POINT, c, 12) for c in CONTROLLERS)
    grade = _grade_primary([succeeded(bt), succeeded(cbf)], [succeeded(relax)])
    return Verdict(grade, "; ".join(describe(r) for r in (bt, cbf, relax)))


def claim_short_horizon_cbf(runs: Runs, model: str) -> Verdict:
    cbf, bt = runs.get(model, POINT, CBF, 5), runs.get(model, POINT, BT, 5)
    bt_struggles = not succeeded(bt) or bool(bt["reversals"])
    return Verdict(_grade_primary([succeeded(cbf)], [bt_struggles]), f"{describe(cbf)}; {describe(bt)}")


def claim_low_gamma(runs: Runs, model: str) -> Verdict:
    cbf, relax = runs.get(model, POINT, CBF, 5, 0.05), runs.get(model, POINT, RELAX, 5, 0.05)
    grade = _grade_primary([succeeded(relax)], [not succeeded(cbf)])
    return Verdict(grade, f"{describe(cbf)}; {describe(relax)}")


def claim_tracking_long(runs: Runs, model: str, scenario: str) -> Verdict:
    rows = [runs.get(model, scenario, BT, 12), runs.get(model, scenario, RELAX, 12, 0.2)]
    return Verdict(_grade([succeeded(r) for r in rows]), "; ".join(describe(r) for r in rows))


def claim_tracking_earlier_smoother(runs: Runs, model: str, scenario: str) -> Verdict:
    bt, relax = runs.get(model, scenario, BT, 5), runs.get(model, scenario, RELAX, 5, 0.12)
    sb, sr = runs.series(bt), runs.series(relax)
    onset_b, onset_r = deviation_onset_s(sb), deviation_onset_s(sr)
    rough_b, rough_r = input_roughness(sb), input_roughness(sr)
    earlier = onset_r is not None and onset_b is not None and onset_r < onset_b  # both measurable
    smoother = rough_r[0] <= rough_b[0] and rough_r[1] <= rough_b[1]
    safe = not relax["collided"]

    def fmt(onset: float | None, rough: tuple[float, float], stopped: float) -> str:
        on = "never" if onset is None else f"{onset:.1f} s"
        return (
            f"onset {on}, RMS dv/dt {rough[0]:.2f} m/s^2, dw/dt {rough[1]:.2f} rad/s^2, "
            f"stopped {stopped:.1f} s"
        )

    evidence = (
        f"{describe(relax)} ({fmt(onset_r, rough_r, stopped_time_s(sr))}); "
        f"{describe(bt)} ({fmt(onset_b, rough_b, stopped_time_s(sb))})"
    )
    return Verdict(_grade_primary([earlier, safe], [smoother]), evidence)


def claim_low_gamma_tracking(runs: Runs, model: str, scenario: str) -> Verdict:
    cbf = runs.get(model, scenario, CBF, 5, 0.03)
    relax = runs.get(model, scenario, RELAX, 5, 0.03)
    grade = _grade_primary([succeeded(relax)], [not succeeded(cbf)])
    return Verdict(grade, f"{describe(cbf)}; {describe(relax)}")


def claim_limits(runs: Runs, model: str) -> Verdict:
    """Commanded v and omega within the configured limits in every run of the paper's controllers."""
    worst_v = worst_w = 0.0
    breaches = 0
    rows = [
        r
        for r in runs.all()
        if r.get("model", "physics") == model and r["controller"] in CONTROLLERS and r["outcome"] != "error"
    ]
    for r in rows:
        s = runs.series(r)
        over_v = max(
            float(np.max(s["v_cmd_mps"])) - float(r["v_max_mps"]),
            float(r["v_min_mps"]) - float(np.min(s["v_cmd_mps"])),
        )
        over_w = float(np.max(np.abs(s["omega_cmd_radps"]))) - float(r["omega_max_radps"])
        worst_v, worst_w = max(worst_v, over_v), max(worst_w, over_w)
        breaches += over_v > 1e-6 or over_w > 1e-6
    what = "commanded (before the drive's own limits)" if model == "physics" else "commanded"
    evidence = (
        f"{len(rows)} runs of {', '.join(CONTROLLERS)}, {what} v in [v_min, v_max] and "
        f"abs(omega) <= omega_max in {len(rows) - breaches}; "
        f"worst excess {worst_v:.2e} m/s, {worst_w:.2e} rad/s"
    )
    return Verdict(REPRODUCED if breaches == 0 else NOT_REPRODUCED, evidence)


def shortest_prediction_time(
    runs: Runs, model: str, scenarios: Sequence[str], controller: str, horizons: Sequence[int]
) -> float | None:
    """Smallest N tau (s) at which the controller succeeds on every listed scenario."""
    for n in sorted(horizons):
        rows = [runs.get(model, s, controller, n) for s in scenarios]
        if all(succeeded(r) for r in rows):
            return n * float(rows[0]["tau_s"])
    return None


def claim_prediction_time(
    runs: Runs, model: str, scenarios: Sequence[str], horizons: Sequence[int], paper: tuple[float, float]
) -> Verdict:
    """The paper's controllers' shortest safe and converging N tau (s) against the paper's BT ->
    Relax-CBF figures `paper` (s)."""
    best = {c: shortest_prediction_time(runs, model, scenarios, c, horizons) for c in CONTROLLERS}
    text = ", ".join(f"{c} {'none' if t is None else f'{t:.1f} s'}" for c, t in best.items())
    bt, relax = best[BT], best[RELAX]
    if relax is not None and bt is not None:
        text += f"; reduction BT -> Relax-CBF {100 * (1 - relax / bt):.2f} %"
    paper_long, paper_short = paper
    text += f" (paper {paper_long:g} s -> {paper_short:g} s, {100 * (1 - paper_short / paper_long):.2f} %)"
    as_short = relax is not None and relax <= paper_short + 1e-9
    if bt is None:  # BT never converges in the scanned range: no reduction can be measured
        text += "; BT never converges in the scanned range"
        return Verdict(PARTLY if relax is not None else NOT_REPRODUCED, text)
    return Verdict(_grade_primary([relax is not None and relax < bt], [as_short]), text)


def claim_ours_prediction_time(runs: Runs, model: str) -> Verdict:
    """husky-cbf's shortest safe and converging N tau (s) on every prediction-time problem, against
    the paper's Relax-CBF figure: reproduced when at most it on every problem, partly on some."""
    if model not in OURS_MODELS:
        return Verdict(
            NOT_APPLICABLE,
            f"{OURS} models the Husky's drive (acceleration limits, dead time, yaw-rate lag); the "
            f"kinematic loop runs only the paper's unicycle controllers",
        )
    checks, parts = [], []
    for p in PREDICTION_TIME_PROBLEMS:
        best = shortest_prediction_time(runs, model, p.scenarios, OURS, p.horizons)
        paper_short = p.paper_s[1]
        checks.append(best is not None and best <= paper_short + 1e-9)
        tau_s = float(runs.get(model, p.scenarios[0], OURS, p.horizons[0])["tau_s"])
        scanned = f"{min(p.horizons) * tau_s:.1f} to {max(p.horizons) * tau_s:.1f} s"
        found = f"none in {scanned}" if best is None else f"{best:.1f} s"
        text = f"{p.name}: {OURS} {found} against the paper's Relax-CBF {paper_short:g} s"
        if best is not None and best <= min(p.horizons) * tau_s + 1e-9:
            text += f" (N = {min(p.horizons)}, the shortest scanned: shorter was not tried)"
        shorter = [n for n in p.horizons if best is None or n * tau_s < best - 1e-9]
        rows = [runs.get(model, s, OURS, n) for n in shorter for s in p.scenarios]
        failed = [f"N={r['horizon']} {r['scenario']} {r['outcome']}" for r in rows if not succeeded(r)]
        parts.append(text + (f"; shorter N fail: {', '.join(failed)}" if failed else ""))
    return Verdict(_grade(checks), "; ".join(parts))


def evaluate(runs: Runs) -> list[ClaimResult]:
    """Every claim, judged on both models."""

    def both(fn: Callable[[Runs, str], Verdict]) -> tuple[Verdict, Verdict]:
        return fn(runs, "kinematic"), fn(runs, "physics")

    claims: list[tuple[str, str, Callable[[Runs, str], Verdict]]] = [
        (
            "Point stabilisation, N >= 12: BT and CBF (and Relax-CBF) reach the goal safely",
            "Sec. IV-A",
            claim_long_horizon,
        ),
        (
            "Point stabilisation, N = 5: CBF reaches the goal while BT stops, reverses or sticks",
            "Sec. IV-A",
            claim_short_horizon_cbf,
        ),
        (
            "Point stabilisation, N = 5, gamma = 0.05: plain CBF fails, Relax-CBF still reaches the goal",
            "Sec. IV-A",
            claim_low_gamma,
        ),
    ]
    for s in TRACKING:
        claims += [
            (
                f"{s}, N = 12: BT and Relax-CBF (gamma = 0.2) track safely",
                "Fig. 4 (a), (b)",
                lambda r, m, s=s: claim_tracking_long(r, m, s),
            ),
            (
                f"{s}, N = 5: Relax-CBF (gamma = 0.12) deviates earlier and is smoother than BT",
                "Fig. 4 (c)",
                lambda r, m, s=s: claim_tracking_earlier_smoother(r, m, s),
            ),
            (
                f"{s}, N = 5, gamma = 0.03: plain CBF fails to track, Relax-CBF tracks",
                "Fig. 4 (d)",
                lambda r, m, s=s: claim_low_gamma_tracking(r, m, s),
            ),
        ]
    claims += [
        (
            "Control signals stay within their limits (every run of the paper's controllers in this report)",
            "Figs. 5, 6",
            claim_limits,
        ),
    ]
    claims += [
        (
            f"Shortest safe and converging N tau, {p.name}",
            "Sec. IV-C",
            lambda r, m, p=p: claim_prediction_time(r, m, p.scenarios, p.horizons, p.paper_s),
        )
        for p in PREDICTION_TIME_PROBLEMS
    ]
    claims += [
        (
            f"Ours: {OURS}, shortest safe and converging N tau in PyBullet on the paper's problems "
            f"(point stabilisation, tau = 0.1 s; Husky point + circle, tau = 0.2 s) is at most the "
            f"paper's Relax-CBF {' s and '.join(f'{p.paper_s[1]:g}' for p in PREDICTION_TIME_PROBLEMS)} s",
            "Sec. IV-C",
            claim_ours_prediction_time,
        ),
    ]
    return [ClaimResult(text, where, *both(fn)) for text, where, fn in claims]


def claims_markdown(results: Sequence[ClaimResult]) -> str:
    lines = [
        "# The paper's claims, checked",
        "",
        "Kinematic: the controller's own unicycle model (the paper's setting; paper scenarios use the",
        "paper's 0.25 m robot circle). PyBullet: the Husky A200 with wheel slip and actuator limits, robot",
        "circle = URDF footprint 0.570 m + the scenario's margin. Definitions: `husky_sim/study/claims.py`.",
        f"Rows that start \"Ours:\" report our controller `{OURS}`, not the paper's: it models the Husky's",
        "drive, so it runs in PyBullet only (its kinematic verdict is `not applicable`).",
        "",
        "| claim | paper | kinematic | evidence (kinematic) | PyBullet | evidence (PyBullet) |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| {r.claim} | {r.paper} | **{r.kinematic.verdict}** | {r.kinematic.evidence} | "
            f"**{r.physics.verdict}** | {r.physics.evidence} |"
        )
    counts = {m: dict.fromkeys(VERDICTS, 0) for m in MODELS}
    for r in results:
        counts["kinematic"][r.kinematic.verdict] += 1
        counts["physics"][r.physics.verdict] += 1
    lines += [
        "",
        "Totals: "
        + "; ".join(
            f"{m}: " + ", ".join(f"{n} {v}" for v, n in c.items() if n or v != NOT_APPLICABLE)
            for m, c in counts.items()
        ),
        "",
    ]
    return "\n".join(lines)


def run_paper_report(out_dir: Path, jobs: int = 2, progress: bool = True) -> list[ClaimResult]:
    # ``out_dir`` receives the physics runs (runs/), results.csv/md, claims.md and claims.json
    """Run every needed cell (both models), judge the claims, write claims.md and claims.json."""
    cells = [c for m in MODELS for c in required_cells(m)]
    rows = run_suite(cells, jobs=jobs, out_dir=out_dir, progress=progress)
    errors = [r for r in rows if r["outcome"] == "error"]
    if errors:
        raise RuntimeError(f"{len(errors)} run(s) failed, first: {errors[0]['error']}")
    results = evaluate(Runs(cells, rows, out_dir))
    (out_dir / "claims.md").write_text(claims_markdown(results))
    (out_dir / "claims.json").write_text(json.dumps([asdict(r) for r in results], indent=2) + "\n")
    return results
