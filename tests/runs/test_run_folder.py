"""Run folders, named, written and read in one place (no physics): what a damaged or foreign
folder gives is one line naming the file, and names never leave the results folder."""

import math
from pathlib import Path

import pytest

from husky_sim.runs.run_folder import (
    RESULTS_DIR,
    RunFolderError,
    default_check_dir,
    default_replay_dir,
    read_log,
    read_results,
    read_summary,
    read_trace,
    summary_or_empty,
    write_results_csv,
    write_summary,
)
from husky_sim.runs.summary import KinematicMetrics, RunSettings, RunSummary


def test_a_summary_round_trips_as_strict_json(tmp_path: Path) -> None:
    write_summary(tmp_path, {"outcome": "reached", "min_clearance_m": math.inf, "steps": 3})
    assert read_summary(tmp_path, ["outcome"]) == {"outcome": "reached", "min_clearance_m": None, "steps": 3}
    with pytest.raises(RunFolderError, match=r"summary.json: not a run summary \(missing horizon\)"):
        read_summary(tmp_path, ["outcome", "horizon"])


def test_a_typed_run_summary_is_written_as_its_flat_record(tmp_path: Path) -> None:
    settings = RunSettings("s", "cbf", 5, 0.1, 7, "kinematic", 0.1, 0.5, -1.0, 1.0, 0.78, "ipopt")
    series = {
        k: [0.0, 0.1] for k in ("t_s", "x_m", "y_m", "ref_x_m", "ref_y_m", "v_cmd_mps", "omega_cmd_radps")
    }
    metrics = KinematicMetrics(
        "timeout",
        False,
        False,
        0.4,
        2.0,
        None,
        None,
        None,
        None,
        None,
        0,
        0,
        1.0,
        0.5,
        3,
        0,
        4.2,
        0,
        0.25,
        2,
        **series,
    )
    write_summary(tmp_path, RunSummary(settings, metrics))
    written = read_summary(tmp_path, ["scenario", "outcome", "t_s"])
    assert written == RunSummary(settings, metrics).as_dict()
    assert list(written)[:6] == ["scenario", "controller", "horizon", "gamma", "seed", "model"]
    assert written["seed"] == 7 and written["robot_radius_m"] == 0.25 and written["x_m"] == [0.0, 0.1]


def test_unusable_folders_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(RunFolderError, match="not a run directory"):
        read_log(tmp_path / "absent")
    with pytest.raises(RunFolderError, match=r"log.csv: missing"):
        read_log(tmp_path)
    (tmp_path / "log.csv").write_text("step,t_s\n")
    with pytest.raises(RunFolderError, match="no control steps logged"):
        read_log(tmp_path)
    (tmp_path / "log.csv").write_text("step,t_s\n0,oops\n")
    with pytest.raises(RunFolderError, match="column t_s is not numeric"):
        read_log(tmp_path, ["t_s"])
    (tmp_path / "trace.npz").write_bytes(b"not a zip")
    with pytest.raises(RunFolderError, match="trace.npz: not a readable"):
        read_trace(tmp_path)
    (tmp_path / "summary.json").write_text("[1, 2]")
    assert summary_or_empty(tmp_path) == {}


def test_results_round_trip_and_need_their_columns(tmp_path: Path) -> None:
    rows = [{"scenario": "a", "outcome": "reached", "plans": [1, 2]}, {"scenario": "b", "extra": 1.5}]
    path = write_results_csv(rows, tmp_path)
    read = read_results(path, ["scenario"])
    assert (
        [r["scenario"] for r in read] == ["a", "b"] and "plans" not in read[0] and read[1]["extra"] == "1.5"
    )
    with pytest.raises(RunFolderError, match="missing columns horizon"):
        read_results(path, ["scenario", "horizon"])


def test_default_folders_stay_under_results() -> None:
    check = default_check_dir("../../etc", "cbf", 5, 32, 0)
    replay = default_replay_dir(Path("/tmp/../my bag.db3"))
    for folder in (check, replay):
        assert folder.parent == RESULTS_DIR and "/" not in folder.name and not folder.name.startswith(".")
    assert check.name == "check__.._.._etc__cbf__N5__K32__s0" and replay.name == "replay__my_bag"
