"""Real Husky A200 drive recordings (DRIVE, Norlab; assets/husky_a200/drive_recordings/README.md) read
into what a calibration needs: steady-state steps and step-response times. Pure numpy and csv.

Two formats, told apart by the CSV header:
- wet-grass raw log (`calib_state`, `calib_step`, ...): rows at 20 Hz; a step is the rows of one
  `calib_step` with `calib_state == "calib"` (6 s of one command), its steady part the rows from 3 s on.
  A step interrupted by the operator (idle rows inside it) or with a gap in its ICP is not a steady step.
- tile windows (`window`, `steady`, ...): 2 s windows of one command step each; one steady step per
  window flagged steady. Step-response times come from the authors' fits beside the file
  (`<name>_authors_fits.csv` for `<name>_windows.csv`), when present.

Every steady step: the body speeds implied by the mean measured wheel speeds (the recordings' own radius
and baseline); the measured yaw rate, the least-squares slope of the ICP yaw; the measured forward speed,
the ICP displacement along the mean heading over the duration divided by sin(a/2)/(a/2), a the angle
turned meanwhile (the chord of an arc is shorter than the arc: without it a 1.5 rad arc reads 9 % slow;
beyond half a turn, the sum of each ICP displacement along its own heading instead).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from husky_sim.paths import ASSETS_DIR

#: The recordings shipped with the project (README.md and the BSD-3-Clause LICENSE beside them).
RECORDINGS_DIR: Path = ASSETS_DIR / "drive_recordings"

RECORDING_WHEEL_RADIUS_M = 0.15875  # the recordings' own constants (README)
RECORDING_BASELINE_M = 0.53846

COMMAND_CLASSES = ("in_place", "tight_arc", "wide_arc", "straight")
#: Upper turning radii (m) of in_place, tight_arc and wide_arc; straight beyond the last.
CLASS_RADII_M = (0.25, 1.0, 4.0)
#: Below this yaw rate (rad/s) a command is straight whatever its speed.
STRAIGHT_YAW_RADPS = 0.05
#: Ratios are undefined below these wheel-implied yaw rate (rad/s) and forward speed (m/s).
MIN_RATIO_YAW_RADPS = 0.1
MIN_RATIO_SPEED_MPS = 0.1

#: Wet grass: the transient dropped at each step's start (s), the shortest steady part kept (s), the
#: longest interval between rows or between ICP updates within a step (s).
STEP_TRANSIENT_S = 3.0
MIN_STEADY_S = 1.0
MAX_GAP_S = 0.5
#: Wet grass wheel step responses: the previous steady value is the mean over the last BEFORE_STEP_S
#: (s) of the previous step; changes of at most MIN_WHEEL_STEP_RADPS (rad/s) are not step responses.
BEFORE_STEP_S = 0.5
MIN_WHEEL_STEP_RADPS = 1.0
#: The fractions of a step's change that define the rise times.
RISE_FRACTIONS = (0.63, 0.95)

WET_GRASS_COLUMNS = ("t_s", "calib_state", "calib_step", "meas_left_vel", "meas_right_vel")
WET_GRASS_ICP_COLUMNS = ("icp_pos_x", "icp_pos_y", "icp_yaw")
WET_GRASS_CURRENT_COLUMNS = ("left_wheel_current", "right_wheel_current")  # optional, both or none
TILE_COLUMNS = (
    "window",
    "step",
    "t_s",
    "steady",
    "left_wheel_vel",
    "right_wheel_vel",
    "imu_yaw",
    "icp_x",
    "icp_y",
    "icp_yaw",
)
FITS_WHEEL_COLUMNS = tuple(
    f"{side}_wheel_vel_time_for_{pct}_percent_ss_value" for side in ("left", "right") for pct in (63, 95)
)
FITS_YAW_COLUMNS = tuple(f"step_frame_vyaw_time_for_{pct}_percent_ss_value" for pct in (63, 95))


class RecordingError(ValueError):
    """A recording that cannot be read; the message is one line naming the file and what is wrong."""


def command_class(v_mps: float, w_radps: float) -> str:
    """Class of a wheel-implied body command by turning radius R = |v|/|w| (m): in_place R < 0.25,
    tight_arc 0.25 <= R < 1.0, wide_arc 1.0 <= R < 4.0, straight otherwise (and |w| < 0.05 rad/s)."""
    if abs(w_radps) < STRAIGHT_YAW_RADPS:
        return "straight"
    radius_m = abs(v_mps) / abs(w_radps)
    for name, upper_m in zip(COMMAND_CLASSES, CLASS_RADII_M, strict=False):
        if radius_m < upper_m:
            return name
    return "straight"


@dataclass(frozen=True)
class SteadyStep:
    """One command held in steady state: wheel speeds (rad/s), body speeds (m/s, rad/s), current (A)."""

    step: int  # the recording's step index (wet grass: calib_step; tile: step)
    window: int  # the tile window's index; -1 for wet grass
    left_radps: float  # measured wheel angular speeds, mean over the steady part (rad/s)
    right_radps: float
    v_wheels_mps: float  # forward speed implied by the measured wheels: r (wR + wL) / 2 (m/s)
    w_wheels_radps: float  # yaw rate implied by the measured wheels: r (wR - wL) / B (rad/s)
    v_mps: float  # measured forward speed, ICP (m/s; module docstring)
    w_radps: float  # measured yaw rate: least-squares slope of the unwrapped ICP yaw (rad/s)
    current_a: float | None  # mean of (|left| + |right|) / 2 motor current (A per motor); None: not logged
    gyro_w_radps: float | None = None  # mean gyro yaw rate (rad/s); None where the gyro was not logged

    @property
    def command_class(self) -> str:
        """Class of the wheel-implied command (COMMAND_CLASSES)."""
        return command_class(self.v_wheels_mps, self.w_wheels_radps)

    @property
    def yaw_ratio(self) -> float | None:
        """Measured / wheel-implied yaw rate; None when |w_wheels| < 0.1 rad/s."""
        if abs(self.w_wheels_radps) < MIN_RATIO_YAW_RADPS:
            return None
        return self.w_radps / self.w_wheels_radps

    @property
    def forward_ratio(self) -> float | None:
        """Measured / wheel-implied forward speed; None when |v_wheels| < 0.1 m/s."""
        if abs(self.v_wheels_mps) < MIN_RATIO_SPEED_MPS:
            return None
        return self.v_mps / self.v_wheels_mps


@dataclass(frozen=True)
class StepTimes:
    """Rise times of one step response, from the command change, delay included (s)."""

    t63_s: float  # to 63 % of the change of the response (s)
    t95_s: float  # to 95 % (s)


@dataclass(frozen=True)
class DriveRecording:
    """A recording's steady steps and step-response times (s)."""

    name: str  # "wet_grass" or "tile" (the file's format)
    path: str
    steps: tuple[SteadyStep, ...]
    wheel_step_times: tuple[StepTimes, ...]  # wheel-speed step responses found in the recording
    yaw_step_times: tuple[StepTimes, ...]  # body yaw-rate step responses (empty where not measured)

    def yaw_ratios(self, command_class: str | None = None) -> tuple[float, ...]:
        """Yaw ratios of the steps of `command_class`; None: of every turning step (not straight)."""
        _check_class(command_class)
        return tuple(
            s.yaw_ratio
            for s in self.steps
            if s.yaw_ratio is not None
            and (s.command_class == command_class if command_class else s.command_class != "straight")
        )

    def forward_ratios(self, command_class: str | None = None) -> tuple[float, ...]:
        """Forward ratios of the steps of `command_class`; None: of every step that has one."""
        _check_class(command_class)
        return tuple(
            s.forward_ratio
            for s in self.steps
            if s.forward_ratio is not None and command_class in (None, s.command_class)
        )

    def median_yaw_ratio(self, command_class: str | None = None) -> float:
        """Median measured / wheel-implied yaw rate over `command_class` (None: all turning steps)."""
        return self._median(self.yaw_ratios(command_class), f"yaw ratio ({command_class or 'turning'})")

    def median_forward_ratio(self, command_class: str | None = None) -> float:
        """Median measured / wheel-implied forward speed over `command_class` (None: all steps)."""
        return self._median(self.forward_ratios(command_class), f"forward ratio ({command_class or 'any'})")

    def median_step_times(self, kind: str) -> StepTimes:
        """Medians of the t63 and of the t95 (s) of the "wheel" or "yaw" step responses."""
        if kind not in ("wheel", "yaw"):
            raise ValueError(f"step time kind must be 'wheel' or 'yaw', not {kind!r}")
        times = self.wheel_step_times if kind == "wheel" else self.yaw_step_times
        if not times:
            raise RecordingError(f"{self.path}: no {kind} step responses in this recording")
        return StepTimes(
            float(np.median([s.t63_s for s in times])), float(np.median([s.t95_s for s in times]))
        )

    def _median(self, values: Sequence[float], what: str) -> float:
        if not values:
            raise RecordingError(f"{self.path}: no steady step has a {what}")
        return float(np.median(values))


def _check_class(name: str | None) -> None:
    if name is not None and name not in COMMAND_CLASSES:
        raise ValueError(f"command class must be one of {COMMAND_CLASSES} or None, not {name!r}")


def load_drive_recording(path: Path) -> DriveRecording:
    """Detect the format from the CSV header (wet-grass raw log, or tile windows) and read it."""
    path = Path(path)
    table = _Table.read(path)
    if "calib_state" in table.columns or "calib_step" in table.columns:
        return _load_wet_grass(table)
    if "window" in table.columns or "steady" in table.columns:
        return _load_tile(table)
    raise RecordingError(
        f"{path}: unknown header (first columns {', '.join(table.columns[:4])}): expected a wet-grass raw "
        "log (calib_state, calib_step, ...) or tile windows (window, steady, ...)"
    )


#: Commands and odometry (a ROS bag): a command must be held this long (s) to give a steady step, whose
#: steady part is its second half.
MIN_HOLD_S = 3.0


def drive_recording_from_commands(
    path: str,
    cmd_t_s: np.ndarray,
    commands: np.ndarray,
    pose_t_s: np.ndarray,
    poses: np.ndarray,
    wheel_separation_multiplier: float,
) -> DriveRecording:
    """Steady steps of a recording that has body commands (v m/s, omega rad/s) and odometry poses
    (x m, y m, yaw rad) but no wheel speeds (a ROS bag of /cmd_vel and odometry): each command held
    for MIN_HOLD_S or longer is a step, measured over its second half. The wheels are taken to run at
    their commands: the wheel-implied body speeds are (v, omega x the drive's separation multiplier),
    as the Husky's diff_drive controller splits them. No currents and no step responses."""
    cmd_t, cmd = np.asarray(cmd_t_s, dtype=float), np.asarray(commands, dtype=float).reshape(-1, 2)
    pose_t, pose = np.asarray(pose_t_s, dtype=float), np.asarray(poses, dtype=float).reshape(-1, 3)
    changes = [0] + [i for i in range(1, len(cmd)) if not np.array_equal(cmd[i], cmd[i - 1])]
    ends = [cmd_t[i] for i in changes[1:]] + [float(pose_t[-1])]
    r, b = RECORDING_WHEEL_RADIUS_M, RECORDING_BASELINE_M
    steps = []
    for index, (first, end) in enumerate(zip(changes, ends, strict=True)):
        start = float(cmd_t[first])
        if end - start < MIN_HOLD_S:
            continue
        inside = (pose_t >= start + 0.5 * (end - start)) & (pose_t < end)
        if np.count_nonzero(inside) < 5 or np.ptp(pose_t[inside]) < MIN_STEADY_S:
            continue
        v, w = cmd[first]
        half = 0.5 * b * w * wheel_separation_multiplier
        n = int(np.count_nonzero(inside))
        left, right = np.full(n, (v - half) / r), np.full(n, (v + half) / r)
        x, y, yaw = pose[inside].T
        steps.append(_steady_step(index, -1, pose_t[inside], left, right, x, y, yaw, None, None))
    if not steps:
        raise RecordingError(f"{path}: no command is held for {MIN_HOLD_S:g} s or longer: no steady step")
    return DriveRecording(Path(path).stem, path, tuple(steps), (), ())


# --- reading ------------------------------------------------------------------------------------------


class _Table:
    """A CSV file's cells by column, with the file line of each row for messages."""

    def __init__(self, path: Path, columns: list[str], rows: list[list[str]], lines: list[int]) -> None:
        self.path, self.columns, self.rows, self.lines = path, columns, rows, lines
        self._index = {name: i for i, name in enumerate(columns)}

    @classmethod
    def read(cls, path: Path) -> _Table:
        try:
            with path.open(newline="", encoding="utf-8") as f:
                reader = csv.reader(f)
                header = next(reader, None)
                rows, lines = [], []
                for row in reader:
                    if row:
                        rows.append(row)
                        lines.append(reader.line_num)
        except FileNotFoundError:
            raise RecordingError(f"{path}: no such file") from None
        except (OSError, UnicodeDecodeError, csv.Error) as e:
            raise RecordingError(f"{path}: cannot be read as CSV ({e})") from None
        if not header:
            raise RecordingError(f"{path}: empty file, no header line")
        columns = [c.strip() for c in header]
        for row, line in zip(rows, lines, strict=True):
            if len(row) != len(columns):
                raise RecordingError(
                    f"{path}: line {line} has {len(row)} fields, the header has {len(columns)}"
                )
        return cls(path, columns, rows, lines)

    def require(self, names: Sequence[str], what: str) -> None:
        missing = [n for n in names if n not in self._index]
        if missing:
            raise RecordingError(f"{self.path}: {what} without column {', '.join(missing)}")

    def text(self, name: str, rows: np.ndarray | None = None) -> list[str]:
        j = self._index[name]
        picked = self.rows if rows is None else [self.rows[i] for i in rows]
        return [row[j].strip() for row in picked]

    def numbers(self, name: str, rows: np.ndarray | None = None, finite: bool = True) -> np.ndarray:
        """The column as floats; a non-numeric cell (or, with `finite`, a nan or inf) is an error.
        Without `finite` an empty cell reads nan."""
        cells = self.text(name, rows)
        if not finite:
            cells = [c or "nan" for c in cells]
        try:
            values = np.array(cells, dtype=float)
        except ValueError:
            values = None
        ok = np.isfinite(values) if values is not None and finite else None
        if values is None or (ok is not None and not ok.all()):
            k = next(
                k
                for k, c in enumerate(cells)
                if not _is_number(c) or (finite and not math.isfinite(float(c)))
            )
            line = self.lines[k if rows is None else int(rows[k])]
            kind = "finite number" if finite else "number"
            raise RecordingError(f"{self.path}: column {name}, line {line}: {cells[k]!r} is not a {kind}")
        return values

    def integers(self, name: str, rows: np.ndarray | None = None) -> np.ndarray:
        values = self.numbers(name, rows)
        bad = np.flatnonzero(values != np.round(values))
        if bad.size:
            line = self.lines[int(bad[0]) if rows is None else int(rows[bad[0]])]
            raise RecordingError(
                f"{self.path}: column {name}, line {line}: {values[bad[0]]} is not an integer"
            )
        return values.astype(int)

    def flags(self, name: str) -> np.ndarray:
        values = {"true": True, "1": True, "false": False, "0": False}
        cells = [c.lower() for c in self.text(name)]
        for k, c in enumerate(cells):
            if c not in values:
                raise RecordingError(
                    f"{self.path}: column {name}, line {self.lines[k]}: {c!r} is not True or False"
                )
        return np.array([values[c] for c in cells], dtype=bool)


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


# --- the steady step ----------------------------------------------------------------------------------


def _steady_step(
    step: int,
    window: int,
    t: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    yaw: np.ndarray,
    current_a: float | None,
    gyro_w_radps: float | None,
) -> SteadyStep:
    """The steady step of samples at times t (s): wheel speeds (rad/s), ICP pose (m, rad)."""
    left_radps, right_radps = float(np.mean(left)), float(np.mean(right))
    yaw = np.unwrap(yaw)
    duration = float(t[-1] - t[0])
    tc = t - np.mean(t)
    w_radps = float(np.sum(tc * (yaw - np.mean(yaw))) / np.sum(tc * tc))
    turned = w_radps * duration
    if abs(turned) <= math.pi:
        heading = math.atan2(float(np.mean(np.sin(yaw))), float(np.mean(np.cos(yaw))))
        along_m = (x[-1] - x[0]) * math.cos(heading) + (y[-1] - y[0]) * math.sin(heading)
        v_mps = along_m / duration / float(np.sinc(turned / (2.0 * math.pi)))  # / (sin(a/2) / (a/2))
    else:  # over more than half a turn a mean heading means little: each displacement along its own
        mid = (yaw[1:] + yaw[:-1]) / 2.0
        v_mps = float(np.sum(np.diff(x) * np.cos(mid) + np.diff(y) * np.sin(mid))) / duration
    r, b = RECORDING_WHEEL_RADIUS_M, RECORDING_BASELINE_M
    return SteadyStep(
        step=step,
        window=window,
        left_radps=left_radps,
        right_radps=right_radps,
        v_wheels_mps=r * (right_radps + left_radps) / 2.0,
        w_wheels_radps=r * (right_radps - left_radps) / b,
        v_mps=float(v_mps),
        w_radps=w_radps,
        current_a=current_a,
        gyro_w_radps=gyro_w_radps,
    )


def rise_times(t: np.ndarray, speed: np.ndarray, before: float, after: float) -> StepTimes | None:
    """Times (s, from t[0]) at which `speed` first covers 63 % and 95 % of before -> after; None if never."""
    covered = (speed - before) / (after - before)
    times = []
    for fraction in RISE_FRACTIONS:
        reached = np.flatnonzero(covered >= fraction)
        if reached.size == 0:
            return None
        times.append(float(t[reached[0]] - t[0]))
    return StepTimes(*times)


# --- wet grass ----------------------------------------------------------------------------------------


def _load_wet_grass(table: _Table) -> DriveRecording:
    table.require(WET_GRASS_COLUMNS + WET_GRASS_ICP_COLUMNS, "wet-grass raw log")
    has_current = any(c in table.columns for c in WET_GRASS_CURRENT_COLUMNS)
    if has_current:
        table.require(WET_GRASS_CURRENT_COLUMNS, "wet-grass raw log with currents")
    rows = np.flatnonzero(np.array([s == "calib" for s in table.text("calib_state")], dtype=bool))
    if rows.size == 0:
        raise RecordingError(f"{table.path}: no row with calib_state 'calib'")
    t = table.numbers("t_s", rows)
    if np.any(np.diff(t) < 0):
        k = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
        raise RecordingError(f"{table.path}: column t_s, line {table.lines[rows[k]]}: time goes backwards")
    ids = table.integers("calib_step", rows)
    left, right = table.numbers("meas_left_vel", rows), table.numbers("meas_right_vel", rows)
    x, y, yaw = (table.numbers(c, rows) for c in WET_GRASS_ICP_COLUMNS)
    current = None
    if has_current:
        current = (np.abs(table.numbers(WET_GRASS_CURRENT_COLUMNS[0], rows))
                   + np.abs(table.numbers(WET_GRASS_CURRENT_COLUMNS[1], rows))) / 2.0  # fmt: skip
    icp_update = np.r_[True, (np.diff(x) != 0) | (np.diff(y) != 0) | (np.diff(yaw) != 0)]

    # Each step: its positions among the calib rows, in the order the steps were run.
    first = {}
    for k, step_id in enumerate(ids.tolist()):
        first.setdefault(step_id, k)
    members = {step_id: np.flatnonzero(ids == step_id) for step_id in sorted(first, key=first.__getitem__)}

    steps, wheel_times = [], []
    for step_id, k in members.items():
        tk = t[k] - t[k[0]]
        steady = k[tk >= STEP_TRANSIENT_S]
        if steady.size < 2 or t[steady[-1]] - t[steady[0]] < MIN_STEADY_S:
            continue
        # An interrupted step, or one whose ICP stalls, is no steady step (its steady part may be a restart).
        updates = np.r_[t[k][icp_update[k] | (k == k[0])], t[k[-1]]]
        intact = np.all(np.diff(rows[k]) == 1) and np.max(np.diff(updates)) <= MAX_GAP_S
        if intact:
            steps.append(
                _steady_step(
                    step_id,
                    -1,
                    t[steady],
                    left[steady],
                    right[steady],
                    x[steady],
                    y[steady],
                    yaw[steady],
                    None if current is None else float(np.mean(current[steady])),
                    None,
                )
            )
        wheel_times += _wheel_step_times(step_id, k, steady, members, rows, t, (left, right))
    return DriveRecording(
        name="wet_grass",
        path=str(table.path),
        steps=tuple(steps),
        wheel_step_times=tuple(wheel_times),
        yaw_step_times=(),
    )


def _wheel_step_times(
    step_id: int,
    k: np.ndarray,
    steady: np.ndarray,
    members: dict[int, np.ndarray],
    rows: np.ndarray,
    t: np.ndarray,
    sides: tuple[np.ndarray, np.ndarray],
) -> list[StepTimes]:
    """The wheel step responses at the start of step `step_id` (positions k among the calib rows): from
    the end of the previous step, when it ran just before, to this step's steady value."""
    prev = members.get(step_id - 1)
    if prev is None or rows[k[0]] != rows[prev[-1]] + 1 or t[k[0]] - t[prev[-1]] > MAX_GAP_S:
        return []
    before_rows = prev[t[prev] >= t[prev[-1]] - BEFORE_STEP_S]
    # The response is looked for until the step's first interruption.
    breaks = np.flatnonzero((np.diff(rows[k]) != 1) | (np.diff(t[k]) > MAX_GAP_S))
    run = k[: breaks[0] + 1] if breaks.size else k
    found = []
    for speed in sides:
        before, after = float(np.mean(speed[before_rows])), float(np.mean(speed[steady]))
        if abs(after - before) > MIN_WHEEL_STEP_RADPS:
            times = rise_times(t[run], speed[run], before, after)
            if times is not None:
                found.append(times)
    return found


# --- tile ---------------------------------------------------------------------------------------------


def _load_tile(table: _Table) -> DriveRecording:
    table.require(TILE_COLUMNS, "tile windows file")
    windows, step_ids, steady = table.integers("window"), table.integers("step"), table.flags("steady")
    t = table.numbers("t_s")
    left, right = table.numbers("left_wheel_vel"), table.numbers("right_wheel_vel")
    gyro = table.numbers("imu_yaw")
    x, y, yaw = table.numbers("icp_x"), table.numbers("icp_y"), table.numbers("icp_yaw")

    order = np.argsort(windows, kind="stable")
    bounds = np.flatnonzero(np.diff(windows[order])) + 1
    groups = sorted(np.split(order, bounds), key=lambda g: int(g[0]))
    steps = []
    for group in groups:
        k = group[np.argsort(t[group], kind="stable")]
        if np.any(step_ids[k] != step_ids[k[0]]):
            line = table.lines[int(k[np.flatnonzero(step_ids[k] != step_ids[k[0]])[0]])]
            raise RecordingError(
                f"{table.path}: column step, line {line}: window {windows[k[0]]} holds more than one step"
            )
        k = k[steady[k]]
        if k.size < 2 or t[k[-1]] - t[k[0]] < MIN_STEADY_S:
            continue
        steps.append(
            _steady_step(
                int(step_ids[k[0]]),
                int(windows[k[0]]),
                t[k],
                left[k],
                right[k],
                x[k],
                y[k],
                yaw[k],
                None,
                float(np.mean(gyro[k])),
            )
        )
    wheel_times: tuple[StepTimes, ...] = ()
    yaw_times: tuple[StepTimes, ...] = ()
    fits = _fits_path(table.path)
    if fits is not None and fits.is_file():
        wheel_times, yaw_times = _read_fits(fits)
    return DriveRecording(
        name="tile",
        path=str(table.path),
        steps=tuple(steps),
        wheel_step_times=wheel_times,
        yaw_step_times=yaw_times,
    )


def _fits_path(windows_path: Path) -> Path | None:
    """The authors' fits beside a `<name>_windows.csv`: `<name>_authors_fits.csv`."""
    if not windows_path.stem.endswith("_windows"):
        return None
    return windows_path.with_name(windows_path.stem.removesuffix("_windows") + "_authors_fits.csv")


def _read_fits(path: Path) -> tuple[tuple[StepTimes, ...], tuple[StepTimes, ...]]:
    """Wheel (one per side per step) and yaw-rate step times of the authors' fits; non-finite dropped."""
    table = _Table.read(path)
    table.require(FITS_WHEEL_COLUMNS + FITS_YAW_COLUMNS, "authors' fits file")
    left63, left95, right63, right95 = (table.numbers(c, finite=False) for c in FITS_WHEEL_COLUMNS)
    yaw63, yaw95 = (table.numbers(c, finite=False) for c in FITS_YAW_COLUMNS)
    wheel = [
        StepTimes(float(a), float(b))
        for row in zip(left63, left95, right63, right95, strict=True)
        for a, b in (row[:2], row[2:])
        if math.isfinite(a) and math.isfinite(b)
    ]
    yaw = [
        StepTimes(float(a), float(b))
        for a, b in zip(yaw63, yaw95, strict=True)
        if math.isfinite(a) and math.isfinite(b)
    ]
    return tuple(wheel), tuple(yaw)
