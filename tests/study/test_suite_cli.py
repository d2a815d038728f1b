"""`husky-sim suite` and the claims report's machinery: matrix, parallel runs, result files,
figures, and the verdict rules (real PyBullet and IPOPT runs, shortened scenarios)."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from husky_sim.cli import main
from husky_sim.runs.scenario import resolve
from husky_sim.study.claims import (
    NOT_REPRODUCED,
    PARTLY,
    REPRODUCED,
    Runs,
    _grade,
    _grade_primary,
    deviation_onset_s,
    input_roughness,
    required_cells,
    stopped_time_s,
)
from husky_sim.study.suite import Cell, markdown_table, matrix, run_suite, standard_matrix, write_figures

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)


def _short_scenario(tmp_path: Path, name: str, duration_s: float) -> Path:
    data = yaml.safe_load(resolve(name).read_text())
    data["duration_s"] = duration_s
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_matrix_order_and_bt_has_one_gamma() -> None:
    cells = matrix(["a"], ["bt", "cbf"], [5, 12], [0.1, 0.2])
    assert [c.label() for c in cells] == [
        "a__bt__N5__g0.1",
        "a__bt__N12__g0.1",
        "a__cbf__N5__g0.1",
        "a__cbf__N12__g0.1",
        "a__cbf__N5__g0.2",
        "a__cbf__N12__g0.2",
    ]


def test_standard_matrix_has_every_controller_and_horizon_and_the_paper_gammas() -> None:
    cells = standard_matrix(["paper_point_stabilisation", "narrow_gap"])
    assert len(cells) == 2 * 3 * 3 + 6
    assert Cell("paper_point_stabilisation", "relax-cbf", 5, 0.05) in cells
    assert all(c.gamma is None for c in cells if c.scenario == "narrow_gap")


def test_suite_runs_in_parallel_and_writes_results_and_figures(tmp_path: Path) -> None:
    scenario = _short_scenario(tmp_path, "husky_point_stabilisation", 4.0)
    out = tmp_path / "suite"
    code = main(
        [
            "suite",
            "--scenarios",
            str(scenario),
            "--controllers",
            "bt",
            "cbf",
            "--horizons",
            "5",
            "--jobs",
            "2",
            "--quiet",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    with (out / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["controller"], r["horizon"]) for r in rows] == [("bt", "5"), ("cbf", "5")]
    for r in rows:
        run_dir = out / r["run_dir"]
        assert (run_dir / "log.csv").is_file() and (run_dir / "trace.npz").is_file()
        ran_to_the_end = r["outcome"] in {"timeout", "tracking"}
        assert (float(r["sim_time_s"]) == pytest.approx(4.0, abs=0.01)) == ran_to_the_end, r["outcome"]
    assert "| husky_point_stabilisation | physics | bt | 5 |" in (out / "results.md").read_text()
    assert (out / "plots" / "comparison_husky_point_stabilisation.png").stat().st_size > 10_000


def test_solver_chooses_the_nlp_backend_of_run_and_suite(tmp_path: Path) -> None:
    """`--solver ipopt`: every step of husky-cbf's run and of a suite's cells solved on IPOPT (the
    default is FATROP), recorded in the log and the summary; the suite labels its runs with it."""
    scenario = str(_short_scenario(tmp_path, "husky_point_stabilisation", 2.0))
    run = tmp_path / "run"
    assert main(["run", scenario, "--controller", "husky-cbf", "--solver", "ipopt", "--out", str(run)]) == 0
    with (run / "log.csv").open() as f:
        assert {r["solver"] for r in csv.DictReader(f)} == {"ipopt"}
    assert '"solver": "ipopt"' in (run / "summary.json").read_text()
    default = tmp_path / "default"
    assert main(["run", scenario, "--controller", "husky-cbf", "--out", str(default)]) == 0
    assert '"solver": "fatrop"' in (default / "summary.json").read_text()
    out = tmp_path / "suite"
    args = ["suite", "--scenarios", scenario, "--controllers", "cbf", "--horizons", "5", "--solver", "ipopt"]
    assert main([*args, "--jobs", "1", "--quiet", "--out", str(out)]) == 0
    with (out / "results.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert row["solver"] == "ipopt" and row["run_dir"].endswith("__ipopt")


def test_figures_are_drawn_scenario_by_scenario_on_worker_processes(tmp_path: Path) -> None:
    """Each scenario's comparison and tuning maps, the same files whether drawn in this process or
    on two workers."""
    names = ("husky_point_stabilisation", "narrow_gap")
    cells = [Cell(str(_short_scenario(tmp_path, name, 1.0)), "bt", 5) for name in names]
    out = tmp_path / "suite"
    rows = run_suite(cells, jobs=1, out_dir=out, progress=False)
    serial = write_figures(rows, out, jobs=1)
    assert write_figures(rows, out, jobs=2) == serial
    expected = [[f"comparison_{name}.png", f"tuning_{name}_bt.png"] for name in names]
    assert [p.name for p in serial] == expected[0] + expected[1]
    assert all(p.stat().st_size > 10_000 for p in serial)


def test_parallel_serial_and_dask_suites_agree(tmp_path: Path) -> None:
    scenario = str(_short_scenario(tmp_path, "head_on_moving_obstacle", 3.0))
    cells = matrix([scenario], ["cbf", "relax-cbf"], [5])
    serial = run_suite(cells, jobs=1, progress=False)
    parallel = run_suite(cells, jobs=2, progress=False)
    on_dask = run_suite(cells, jobs=2, progress=False, backend="dask")
    for a, b, c in zip(serial, parallel, on_dask, strict=True):
        for key in ("outcome", "min_clearance_m", "final_position_error_m", "safety_active_steps"):
            assert a[key] == b[key] == c[key], key


def test_a_crashing_cell_is_reported_not_raised() -> None:
    rows = run_suite([Cell("no_such_scenario", "bt", 5)], jobs=1, progress=False)
    assert rows[0]["outcome"] == "error" and "no_such_scenario" in rows[0]["error"]


def test_markdown_table_formats_missing_and_float_values() -> None:
    text = markdown_table(
        [{"scenario": "s", "horizon": 5, "min_clearance_m": 0.12345, "outcome": None}],
        ("scenario", "horizon", "min_clearance_m", "outcome"),
    )
    assert text.splitlines()[2] == "| s | 5 | 0.123 | - |"


def test_cli_errors_are_one_line_with_exit_code_2(tmp_path: Path) -> None:
    husky_sim = Path(sys.executable).with_name("husky-sim")
    for args in (
        ["suite", "--scenarios", "no_such_scenario"],
        ["suite", "--horizons", "0"],
        ["suite", "--scheduler", "tcp://127.0.0.1:8786"],  # needs --backend dask
        ["run", "nope"],
        ["run", "husky_point_stabilisation", "--solver", "opti"],  # bench's baseline only
    ):
        proc = subprocess.run([str(husky_sim), *args], capture_output=True, text=True, cwd=tmp_path)
        assert proc.returncode == 2, args
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert "Traceback" not in proc.stderr


def test_grade() -> None:
    assert _grade([True, True]) == REPRODUCED
    assert _grade([True, False]) == PARTLY
    assert _grade([False, False]) == NOT_REPRODUCED
    assert _grade_primary([True], [True]) == REPRODUCED
    assert _grade_primary([True], [False]) == PARTLY
    assert _grade_primary([False], [True]) == NOT_REPRODUCED  # the contrast alone proves nothing


def _series(err: np.ndarray, v: np.ndarray, w: np.ndarray, dt: float = 0.1) -> dict[str, np.ndarray]:
    t = dt * np.arange(len(err))
    return {
        "t_s": t,
        "x_m": err,
        "y_m": 0 * t,
        "ref_x_m": 0 * t,
        "ref_y_m": 0 * t,
        "v_cmd_mps": v,
        "omega_cmd_radps": w,
    }


def test_deviation_onset_smoothness_and_stopped_time() -> None:
    err = np.array([0.5, 0.3, 0.05, 0.08, 0.15, 0.25, 0.4, 0.1])
    s = _series(err, np.array([1, 1, 1, 0, 0, 0, 1, 1.0]), np.array([0, 0.1, 0, 0.1, 0, 0, 0, 0.0]))
    assert deviation_onset_s(s) == pytest.approx(0.5)  # first > 0.2 m after first < 0.1 m
    assert deviation_onset_s(_series(err[:2], np.ones(2), np.zeros(2))) is None  # never near
    rough_v, rough_w = input_roughness(s)
    assert rough_v == pytest.approx(np.sqrt(2 * 10.0**2 / 7))
    assert rough_w == pytest.approx(np.sqrt(4 * 1.0**2 / 7))
    assert stopped_time_s(s) == pytest.approx(0.1)  # only step 5 is stopped and > 0.2 m off


def test_claims_read_physics_series_from_the_run_log(tmp_path: Path) -> None:
    scenario = str(_short_scenario(tmp_path, "husky_circle_tracking", 2.0))
    cells = [Cell(scenario, "cbf", 5)]
    rows = run_suite(cells, jobs=1, out_dir=tmp_path / "out", progress=False)
    series = Runs(cells, rows, tmp_path / "out").series(rows[0])
    assert len(series["t_s"]) == rows[0]["steps"] and series["x_m"][0] == pytest.approx(2.5, abs=0.01)


def test_required_cells_cover_every_claim_and_kinematic_runs_use_the_papers_radius() -> None:
    cells = required_cells("kinematic")
    assert len(cells) == len(set(cells))
    assert all(c.robot_radius_m == 0.25 for c in cells if c.scenario.startswith("paper_"))
    assert all(c.robot_radius_m is None for c in required_cells("physics"))


def _row(controller: str, horizon: int, gamma: float | None, ok: bool, **extra: object) -> dict[str, object]:
    t = np.arange(50) * 0.1
    row = {
        "controller": controller,
        "horizon": horizon,
        "gamma": gamma,
        "tau_s": 0.1,
        "model": "kinematic",
        "outcome": "reached" if ok else "stuck",
        "converged": ok,
        "collided": False,
        "min_clearance_m": 0.2,
        "final_position_error_m": 0.0 if ok else 3.0,
        "reversals": 0,
        "v_min_mps": -1.0,
        "v_max_mps": 1.0,
        "omega_max_radps": 0.8,
        "t_s": t,
        "x_m": 0 * t,
        "y_m": 0 * t,
        "ref_x_m": 0 * t,
        "ref_y_m": 0 * t,
        "v_cmd_mps": 0 * t,
        "omega_cmd_radps": 0 * t,
    }
    row.update(extra)
    return row


def _runs(rows: dict[tuple, dict[str, object]]) -> Runs:
    from husky_sim.study.claims import _cell

    cells = [_cell("kinematic", *key) for key in rows]
    return Runs(cells, list(rows.values()), Path("."))


def test_prediction_time_needs_bt_to_converge_somewhere_for_a_reduction() -> None:
    from husky_sim.study.claims import POINT, claim_prediction_time

    ok_from = {"bt": None, "cbf": None, "relax-cbf": 5}
    rows = {
        (POINT, c, n): _row(c, n, None, ok_from[c] is not None and n >= ok_from[c])
        for c in ("bt", "cbf", "relax-cbf")
        for n in (5, 12)
    }
    verdict = claim_prediction_time(_runs(rows), "kinematic", [POINT], (5, 12), (1.2, 0.5))
    assert verdict.verdict == PARTLY and "BT never converges" in verdict.evidence
    ok_from["bt"] = 12
    rows = {
        (POINT, c, n): _row(c, n, None, ok_from[c] is not None and n >= ok_from[c])
        for c in ("bt", "cbf", "relax-cbf")
        for n in (5, 12)
    }
    verdict = claim_prediction_time(_runs(rows), "kinematic", [POINT], (5, 12), (1.2, 0.5))
    assert verdict.verdict == REPRODUCED and "58.33 %" in verdict.evidence


def test_limits_claim_checks_signed_commanded_bounds() -> None:
    from husky_sim.study.claims import POINT, claim_limits

    row = _row("bt", 5, None, True)
    assert claim_limits(_runs({(POINT, "bt", 5): row}), "kinematic").verdict == REPRODUCED
    reverse = dict(row, v_min_mps=-0.5, v_cmd_mps=np.full(50, -0.8))  # inside |v| <= 1, below v_min
    assert claim_limits(_runs({(POINT, "bt", 5): reverse}), "kinematic").verdict == NOT_REPRODUCED


def test_earlier_deviation_needs_both_onsets_measurable() -> None:
    from husky_sim.study.claims import claim_tracking_earlier_smoother

    s = "paper_dynamic_tracking"
    err = np.r_[np.full(10, 0.05), np.full(40, 0.5)]  # near, then deviates at t = 1.0 s
    relax = _row("relax-cbf", 5, 0.12, True, x_m=err)
    never_near = _row("bt", 5, None, True, x_m=np.full(50, 0.5))
    runs = _runs({(s, "bt", 5): never_near, (s, "relax-cbf", 5, 0.12): relax})
    verdict = claim_tracking_earlier_smoother(runs, "kinematic", s)
    assert verdict.verdict == NOT_REPRODUCED
    later = _row("bt", 5, None, True, x_m=np.r_[np.full(20, 0.05), np.full(30, 0.5)])
    runs = _runs({(s, "bt", 5): later, (s, "relax-cbf", 5, 0.12): relax})
    verdict = claim_tracking_earlier_smoother(runs, "kinematic", s)
    assert verdict.verdict == REPRODUCED


def test_kinematic_tracking_run_shorter_than_settle_time_has_no_rmse_and_does_not_converge() -> None:
    from husky_sim.runs.run import run_scenario_kinematic
    from husky_sim.runs.scenario import load_scenario

    sc = load_scenario("husky_circle_tracking").model_copy(update={"duration_s": 1.0})
    metrics = run_scenario_kinematic(sc, "cbf", 5).metrics
    assert metrics.tracking_rmse_m is None and metrics.converged is False


def test_results_md_explains_every_outcome_word_it_shows() -> None:
    from husky_sim.sim.metrics import OUTCOME_MEANINGS
    from husky_sim.study.suite import outcome_legend

    rows = [
        {"controller": "bt", "outcome": "stuck", "final_position_error_m": 6.5},
        {"controller": "cbf", "outcome": "stuck", "final_position_error_m": 0.28},
        {"controller": "relax-cbf", "outcome": "collided", "final_position_error_m": 3.0},
        {"controller": "cbf", "outcome": "error"},
    ]
    text = outcome_legend(rows)
    for word in ("stuck", "collided", "error"):
        assert f"- `{word}`: {OUTCOME_MEANINGS[word]}" in text
    assert "- `reached`" not in text  # only the words the table shows
    assert "2 of 4 runs are `stuck`" in text and "1 of the stuck runs" in text and "beside" in text


def test_results_md_says_why_the_paper_controllers_fail_and_what_husky_cbf_changes() -> None:
    from husky_sim.study.suite import OURS, OURS_NOTE, PAPER_COLLISION_NOTE, outcome_legend

    paper_only = [
        {"controller": "bt", "outcome": "collided", "final_position_error_m": 4.0},
        {"controller": "relax-cbf", "outcome": "stuck", "final_position_error_m": 6.5},
    ]
    text = outcome_legend(paper_only)
    assert "1 runs of BT or Relax-CBF are `collided`" in text and PAPER_COLLISION_NOTE in text
    assert OURS_NOTE not in text and "0.82 m" in text  # the deadlock note names the circle
    ours = [{"controller": OURS, "outcome": "reached"}, {"controller": OURS, "outcome": "timeout"}]
    text = outcome_legend(paper_only + ours)
    assert OURS_NOTE in text and "three 0.38 m discs" in text
    assert f"- `{OURS}`: 1 `reached`, 1 `timeout` (of 2)" in text
    assert "- `bt`: 1 `collided` (of 1)" in text
