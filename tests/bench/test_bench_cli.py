"""`husky-sim bench` runs real closed loops with both backends and prints the documented JSON."""

import json

import pytest

from husky_sim.cli import main


def test_bench_json_records(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "bench",
            "--json",
            "--steps",
            "4",
            "--controllers",
            "relax-cbf",
            "bt",
            "--horizons",
            "5",
            "--obstacles",
            "1",
            "7",
        ]
    )
    assert code == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 2 * 2 * 3
    keys = {
        "variant",
        "horizon",
        "obstacles",
        "solver",
        "default",
        "median_ms",
        "p95_ms",
        "p99_ms",
        "max_ms",
        "cpu_median_ms",
        "cpu_p99_ms",
        "steps",
        "fallbacks",
        "first_control_diff_p99",
    }
    for rec in records:
        assert set(rec) == keys
        assert rec["horizon"] == 5 and rec["obstacles"] in (1, 7) and rec["steps"] == 4
        assert 0 < rec["median_ms"] <= rec["p95_ms"] <= rec["p99_ms"] <= rec["max_ms"]
        assert 0 < rec["cpu_median_ms"] <= rec["cpu_p99_ms"]
        assert rec["fallbacks"] == 0
        assert rec["default"] == (rec["solver"] == "fatrop")
        if rec["solver"] == "ipopt":
            assert rec["first_control_diff_p99"] is None
        else:
            assert 0 <= rec["first_control_diff_p99"] < 1e-4
    assert {rec["solver"] for rec in records} == {"fatrop", "ipopt", "opti"}


def test_bench_table_has_ratio(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--steps", "3", "--controllers", "cbf", "--horizons", "5", "--obstacles", "1"]) == 0
    out = capsys.readouterr().out
    assert "| cbf | 5 | 1 |" in out and "x |" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "--horizons", "0"],
        ["bench", "--steps", "-2"],
        ["bench", "--gamma", "1.5"],
        ["bench", "--controllers", "mode3"],
        ["bench", "--obstacles", "9"],
        ["bench", "--solvers", "hpipm"],
        ["bench-sim", "--solver", "opti"],
    ],
)
def test_bench_bad_input_exits_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2  # main returns the exit code for usage mistakes too
    assert "error:" in capsys.readouterr().err


@pytest.mark.physics
def test_bench_sim_reports_real_time_factors() -> None:
    from husky_sim.bench.closed_loop import run_sim_bench

    bench = run_sim_bench(duration_s=1.0, stepping_steps=240)
    assert bench.episode_sim_s == pytest.approx(1.0)
    assert bench.episode_wall_s > 0 and bench.stepping_wall_s > 0 and bench.checked_stepping_wall_s > 0
    assert 0 < bench.peak_rss_mb < 2000
    assert "x real time" in bench.report()
