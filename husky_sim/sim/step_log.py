"""The per-control-step log (`log.csv`): its columns, the writer that flushes each row at once (a
run that is interrupted or fails keeps what it logged) and the comparison used for determinism.
The reader is husky_sim.runs.run_folder.read_log."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

#: One row per control step at time t_s: the true pose, body velocity and wheel speeds at t_s,
#: the reference at t_s, the command issued at t_s (`*_cmd`) and the drive's limited command at
#: the end of the step (`*_applied`), the smallest clearance (m) to obstacles and walls over the
#: step's physics steps, whether the reference point at t_s was reachable (1: outside every
#: obstacle's circle at t_s inflated by the footprint radius; outcomes.reference_reachable), and
#: the solve's slacks, activity, status and wall time; `repeated` is 1 where the step ran no solver,
#: every problem it posed having been answered before, bit for bit (controllers.backends.repeats).
#: `visible_obstacles` lists the obstacles the controller was told of at t_s (format_visible);
#: `mode` names the behaviour whose target the plan tracked ("" for a controller without any).
LOG_COLUMNS = (
    "step",
    "t_s",
    "x_m",
    "y_m",
    "yaw_rad",
    "ref_x_m",
    "ref_y_m",
    "ref_yaw_rad",
    "v_cmd_mps",
    "omega_cmd_radps",
    "v_applied_mps",
    "omega_applied_radps",
    "v_body_mps",
    "omega_body_radps",
    "wheel_l1_radps",
    "wheel_l2_radps",
    "wheel_r1_radps",
    "wheel_r2_radps",
    "motor_left_a",
    "motor_right_a",
    "clearance_m",
    "ref_reachable",
    "visible_obstacles",
    "s_h_min",
    "s_v_max",
    "safety_active",
    "iterations",
    "status",
    "solver",
    "solver_fallback",
    "repeated",
    "fallback",
    "recovered_by",
    "soft_constraint",
    "guided",
    "mode",
    "escape",
    "filtered",
    "deadline_miss",
    "solve_ms",
)
#: Columns whose values are wall-clock measurements (excluded from determinism comparisons).
WALL_CLOCK_COLUMNS = ("solve_ms",)


#: Between the indices of `visible_obstacles`.
VISIBLE_SEPARATOR = ";"


def format_visible(indices: Sequence[int]) -> str:
    """The `visible_obstacles` column: the indices (in the scenario's obstacle order) of the
    obstacles the controller was told of, ascending, joined by ";" ("0;2;5"; "" for none). With
    sensing latency they are those seen latency_steps before (husky_sim.sim.sensing)."""
    return VISIBLE_SEPARATOR.join(str(int(i)) for i in indices)


def parse_visible(value: object) -> tuple[int, ...]:
    """The indices of a `visible_obstacles` value, as written or as read back by a CSV reader
    that made a number of a lone index ("3", 3.0) or NaN of an empty cell."""
    if isinstance(value, float):
        return () if value != value else (int(value),)
    if isinstance(value, int):
        return (int(value),)
    text = str(value).strip()
    return tuple(int(float(part)) for part in text.split(VISIBLE_SEPARATOR)) if text else ()


class StepLog:
    """The CSV log, flushed row by row; `StepLog(None)` logs nothing (a run without a folder)."""

    def __init__(self, path: Path | None) -> None:
        self._file = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file = path.open("w", newline="")
            self._writer = csv.DictWriter(self._file, fieldnames=LOG_COLUMNS)
            self._writer.writeheader()
            self._file.flush()

    def write(self, row: dict[str, object]) -> None:
        if self._file is not None:
            self._writer.writerow({k: _fmt(row[k]) for k in LOG_COLUMNS})
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


def _fmt(value: object) -> object:
    return f"{value:.9g}" if isinstance(value, float) else value


def compare_logs(a: Sequence[dict[str, object]], b: Sequence[dict[str, object]]) -> list[str]:
    """Columns (other than wall-clock ones) that differ between two logs; empty if identical."""
    if len(a) != len(b):
        return ["length"]
    diff = set()
    for ra, rb in zip(a, b, strict=True):
        for key in LOG_COLUMNS:
            if key not in WALL_CLOCK_COLUMNS and ra[key] != rb[key]:
                diff.add(key)
    return sorted(diff)
