"""`husky-sim bench-sim` on the large world: a real closed loop among 1,000 static obstacles, its
real-time factor against wall and CPU time, its solve times and its physics step's cost."""

from __future__ import annotations

import pytest

from husky_sim.cli import main


@pytest.mark.physics
def test_the_large_world_bench_reports_its_figures() -> None:
    from husky_sim.bench.closed_loop import run_large_world_bench

    bench = run_large_world_bench("husky-cbf", duration_s=0.5, stepping_steps=48)
    assert bench.obstacles == 1000 and bench.episode_sim_s == pytest.approx(0.5)
    assert bench.control_steps == 5 and 0 < bench.solve_ms_median <= bench.solve_ms_p99
    assert bench.episode_wall_s > bench.solve_total_s > 0 and bench.episode_cpu_s > 0
    assert bench.stepping_steps == 48 and bench.stepping_wall_s > 0
    assert bench.checked_stepping_wall_s > 0 and bench.checked_stepping_cpu_s > 0
    report = bench.report()
    assert "1000 static obstacles" in report and "x real time" in report and "p99" in report


@pytest.mark.physics
def test_bench_sim_prints_the_large_world(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench-sim", "--world", "large", "--controller", "cbf", "--duration", "0.3"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("large world (large_world_1000: 1000 static obstacles, cbf")
    assert "closed-loop episode (relax-cbf" not in out  # the small world was not asked for


@pytest.mark.parametrize("argv", [["bench-sim", "--world", "huge"], ["bench-sim", "--controller", "mode3"]])
def test_bench_sim_bad_choices_exit_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    assert "error:" in capsys.readouterr().err
