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


def test_a_summary_round_trips_as_strict_json(tmp_path: Path) -> None:
    write_summary(tmp_path, {"outcome": "reached", "min_clearance_m": math.inf, "steps": 3})
    assert read_summary(tmp_path, ["outcome"]) == {"outcome": "reached", "min_clearance_m": None, "steps": 3}
    with pytest.raises(RunFolderError, match=r"summary.json: not a run summary \(missing horizon\)"):
        read_summary(tmp_path, ["outcome", "horizon"])


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
