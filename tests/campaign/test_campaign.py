"""Campaigns and the falsifier, end to end: real layouts, real PyBullet runs, real solvers.

campaign.csv's `solve_ms_p99` is the one wall-clock column: comparisons of two campaigns leave it
out (every other column is a function of the layouts, the controller and the code)."""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from husky_sim.campaign.stats import run_class, upper_bound
from husky_sim.cli import main
from husky_sim.runs.run import run_scenario
from husky_sim.runs.scenario import load_scenario

pytestmark = pytest.mark.physics

#: A short campaign: two short crossings with husky-cbf at N = 5.
CAMPAIGN = [
    "campaign", "--families", "crossing_walkers", "--controller", "husky-cbf", "--count", "2",
    "--seed", "7", "--horizon", "5", "--param", "length_m=8", "--param", "walkers=1", "--quiet",
]  # fmt: skip
WALL_CLOCK = ("solve_ms_p99",)


def _rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "campaign.csv").open(newline="") as f:
        return [{k: v for k, v in row.items() if k not in WALL_CLOCK} for row in csv.DictReader(f)]


@pytest.fixture(scope="module")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("straight")
    assert main([*CAMPAIGN, "--jobs", "1", "--out", str(out)]) == 0
    return out


def test_a_campaign_writes_a_row_per_run_and_a_report(straight: Path) -> None:
    rows = _rows(straight)
    assert [r["layout"] for r in rows] == ["crossing_walkers-s7-000", "crossing_walkers-s7-001"]
    assert all(r["class"] for r in rows) and all(r["controller"] == "husky-cbf" for r in rows)
    for row in rows:  # the controller's own counts, as its run's summary has them
        summary = json.loads((straight / "runs" / row["layout"] / "summary.json").read_text())
        assert int(row["mode_changes"]) == summary["mode_changes"] > 0
        assert int(row["filter_interventions"]) == summary["filter_interventions"]
    report = (straight / "campaign.md").read_text()
    assert "| crossing_walkers | 2 |" in report and "husky-sim campaign --families crossing_walkers" in report
    assert (straight / "figures" / "crossing_walkers.png").is_file()


def test_bench_campaign_reads_every_run_and_every_step(straight: Path) -> None:
    from husky_sim.bench.campaign_speed import campaign_speed

    speed = campaign_speed(straight)
    steps = 0
    for run_dir in sorted((straight / "runs").iterdir()):
        with (run_dir / "log.csv").open(newline="") as f:
            steps += sum(1 for _ in csv.DictReader(f))
    assert speed.runs == 2 and speed.steps == steps and speed.tau_s == pytest.approx(0.1)
    assert 0.0 < speed.step_ms_median <= speed.step_ms_p99 <= speed.step_ms_max
    assert speed.real_time_factor_p10 <= speed.real_time_factor_median
    assert "real-time factor: median" in speed.report() and "p99" in speed.report()


def test_a_killed_campaign_restarted_writes_the_same_csv(straight: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "husky_sim.cli", *CAMPAIGN, "--jobs", "1", "--out", str(out)]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    first = out / "runs" / "crossing_walkers-s7-000" / "summary.json"
    deadline = time.monotonic() + 300
    while not first.is_file() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert first.is_file(), f"the first run finished (exit {proc.poll()})"
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    partial = _rows(out)
    assert [r["layout"] for r in partial] == ["crossing_walkers-s7-000"], "the finished run is kept"
    second = out / "runs" / "crossing_walkers-s7-001" / "summary.json"
    if second.is_file():  # killed mid-run: the run is marked so and done again
        assert json.loads(second.read_text())["outcome"] == "interrupted"
    kept = first.stat().st_mtime_ns
    assert main([*CAMPAIGN, "--jobs", "1", "--out", str(out)]) == 0
    assert first.stat().st_mtime_ns == kept, "the finished run was not run again"
    assert _rows(out) == _rows(straight)


def test_a_campaign_runs_on_a_dask_scheduler_the_test_starts(straight: Path, tmp_path: Path) -> None:
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        out = tmp_path / "dask"
        args = [*CAMPAIGN, "--backend", "dask", "--scheduler", cluster.scheduler_address, "--out", str(out)]
        assert main(args) == 0
    assert _rows(out) == _rows(straight)


def test_a_restart_with_another_command_in_the_same_folder_is_refused(
    straight: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = (straight / "campaign.csv").read_bytes()
    args = [*CAMPAIGN, "--jobs", "1", "--out", str(straight)]
    args[args.index("--count") + 1] = "3"
    assert main(args) == 2
    assert "holds another campaign" in capsys.readouterr().err
    assert (straight / "campaign.csv").read_bytes() == before


def test_a_failing_layout_is_saved_and_husky_sim_run_reproduces_it(tmp_path: Path) -> None:
    """The paper's relax-cbf at N = 12 drives into a walker of this layout (a measured failure:
    if the controller or the family changes, pick another failing layout)."""
    out = tmp_path / "c"
    args = ["campaign", "--families", "crossing_walkers", "--controller", "relax-cbf", "--count", "1"]
    assert main([*args, "--seed", "3", "--horizon", "12", "--jobs", "1", "--quiet", "--out", str(out)]) == 0
    (row,) = list(csv.DictReader((out / "campaign.csv").open()))
    assert row["class"] == "collision_at_fault"
    failure = out / "failures" / "crossing_walkers-s3-000.yaml"
    assert "reproduce: husky-sim run" in failure.read_text()
    again = run_scenario(load_scenario(str(failure)), "relax-cbf").as_dict()
    assert again["outcome"] == row["outcome"] and again["horizon"] == 12
    assert round(again["min_clearance_m"], 4) == float(row["min_clearance_m"])
    assert "crossing_walkers-s3-000" in (out / "campaign.md").read_text()


def test_falsify_writes_its_history_the_worst_layout_and_a_figure_for_both_methods(tmp_path: Path) -> None:
    args = ["falsify", "crossing_walkers", "--controller", "relax-cbf", "--budget", "3", "--method", "both"]
    args += ["--seed", "2", "--horizon", "5", "--param", "length_m=8", "--jobs", "1", "--out", str(tmp_path)]
    assert main(args) == 0
    for method in ("cma", "random"):
        with (tmp_path / method / "falsify.csv").open(newline="") as f:
            history = list(csv.DictReader(f))
        assert [h["method"] for h in history] == [method] * 3
        assert all(float(h["length_m"]) == 8.0 for h in history)
        best = min(float(h["score"]) for h in history)
        assert float(history[-1]["best_score"]) == best
        worst = tmp_path / method / "worst.yaml"
        assert f"score {best:.4f}" in worst.read_text()
        assert (tmp_path / method / "falsify.png").is_file()
    table = (tmp_path / "falsify.md").read_text().splitlines()
    assert [row.split(" | ")[2] for row in table[2:]] == ["cma", "random"]


def test_failure_classes_and_their_bounds() -> None:
    assert (
        run_class({"outcome": "collided", "collided": True, "collision_at_fault": True})
        == "collision_at_fault"
    )
    assert run_class({"outcome": "collided", "collided": True, "collision_at_fault": False}) == "hit_standing"
    assert run_class({"outcome": "tracking", "converged": False}) == "tracking_lost"
    assert run_class({"outcome": "tracking", "converged": True}) == "reached"
    assert run_class({"outcome": "stuck"}) == "stuck"
    # the exact one-sided bound: 0 of n -> 1 - 0.05^(1/n); 2 of 25 from the beta quantile
    assert upper_bound(0, 25) == pytest.approx(1 - 0.05 ** (1 / 25))
    from scipy.stats import beta

    assert upper_bound(2, 25) == pytest.approx(beta.ppf(0.95, 3, 23))
