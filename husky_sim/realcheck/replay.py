"""`husky-sim replay`: drive the simulated Husky with the velocity commands of a real recording and
measure how far the simulated trajectory drifts from the recorded one.

Inputs
  * a ROS 1 bag (`.bag`) or a ROS 2 bag (a directory with metadata.yaml, sqlite3 or mcap storage),
    read with `rosbags.highlevel.AnyReader`: commands are geometry_msgs/Twist or TwistStamped
    (linear.x in m/s, angular.z in rad/s), poses are nav_msgs/Odometry (pose.pose: x, y in m, yaw
    from the orientation quaternion). Every message is timed by its bag (receive) timestamp, so
    commands and poses share one clock whatever their headers say.
  * a CSV file with the header `t,v,omega,x,y,theta`: time t (s), commanded linear speed v (m/s)
    and yaw rate omega (rad/s), and the recorded pose x, y (m) and heading theta (rad). A row may
    leave the command cells or the pose cells empty when it carries only the other.

Replay
  The simulation starts at rest at the first recorded pose, at the time of that pose, and runs
  until the last recorded pose. Commands are held (zero-order hold) from their timestamps, the
  last one before the first pose included; before any command the robot is commanded to stand
  still. Each physics step goes through the drive's velocity/acceleration limits and wheel-speed
  split, as in a closed-loop episode (husky_sim.sim.episode).

Divergence (at the recorded pose times; the simulated pose is interpolated between physics steps)
  * absolute trajectory error: RMSE and maximum of the position error (m);
  * drift per metre: final position error / recorded path length (m/m).

It also fits the recording's yaw-rate lag (husky_sim.sim.yaw_response: the recorded commands
through the drive's limits against the recorded yaw rate, from the odometry twist when the
recording has a non-zero one, else from the differentiated yaw) and prints it as `robot:
yaw_response` scenario parameters. Fitting the simulated ground itself to a recording is
`husky-sim calibrate` (husky_sim.calibration), the one fitting path.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from controllers.model import wrap_angle
from husky_sim.extras import require
from husky_sim.sim.drive import DriveConfig, SkidSteerDrive
from husky_sim.sim.ground import Ground, load_ground, with_friction
from husky_sim.sim.open_loop import held_commands, simulate_commands
from husky_sim.sim.world import WorldConfig
from husky_sim.sim.yaw_response import YawResponse, fit_yaw_response, interval_means

CSV_COLUMNS = ("t", "v", "omega", "x", "y", "theta")
TWIST_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
SUMMARY_NAME = "replay_summary.json"
PLOT_NAME = "replay.png"


class ReplayError(ValueError):
    """An input that cannot be replayed; the message is one line."""


@dataclass(frozen=True)
class SimParams:
    """The simulator parameters a replay sets; everything else keeps its default."""

    wheel_separation_multiplier: float = DriveConfig().wheel_separation_multiplier  # dimensionless
    ground_friction: float = WorldConfig().ground_friction  # ground friction coefficient
    physics_hz: float = WorldConfig().physics_hz  # Hz

    def world(self) -> WorldConfig:
        return WorldConfig(physics_hz=self.physics_hz, ground_friction=self.ground_friction)

    def drive(self) -> DriveConfig:
        return DriveConfig(wheel_separation_multiplier=self.wheel_separation_multiplier)

    def ground(self) -> Ground:
        """The default ground with this tyre friction coefficient."""
        return with_friction(load_ground(), self.ground_friction)

    def scenario_yaml(self, yaw_response: YawResponse | None = None) -> str:
        """The parameters as a scenario snippet (husky_sim.runs.scenario: drive, friction.ground, and
        robot.yaw_response when one is given)."""
        text = (
            f"drive: {{wheel_separation_multiplier: {self.wheel_separation_multiplier:.4g}}}\n"
            f"friction: {{ground: {self.ground_friction:.4g}}}"
        )
        if yaw_response is not None:
            text += (
                f"\nrobot: {{yaw_response: {{gain: {yaw_response.gain:.4g}, "
                f"time_constant_s: {yaw_response.time_constant_s:.4g}}}}}"
            )
        return text


# --------------------------------------------------------------------------------------------
# recordings


@dataclass(frozen=True)
class Recording:
    """Commands and poses of one recorded drive; times in s after the first recorded pose."""

    source: str
    format: str  # "ros1", "ros2" or "csv"
    cmd_t_s: np.ndarray  # (n,) s, sorted; may be negative (sent before the first pose)
    commands: np.ndarray  # (n, 2) v (m/s), omega (rad/s)
    pose_t_s: np.ndarray  # (m,) s, sorted, pose_t_s[0] == 0
    poses: np.ndarray  # (m, 3) x (m), y (m), yaw (rad)
    yaw_rates: np.ndarray | None = None  # (m,) odometry twist yaw rate (rad/s) at pose_t_s, if recorded

    @property
    def start(self) -> tuple[float, float, float]:
        x, y, yaw = self.poses[0]
        return float(x), float(y), float(yaw)

    @property
    def duration_s(self) -> float:
        return float(self.pose_t_s[-1])

    def path_length_m(self) -> float:
        """Length of the recorded xy polyline (m)."""
        return float(np.sum(np.hypot(*np.diff(self.poses[:, :2], axis=0).T)))


#: Longest recording replayed (s): as long as the longest scenario (an hour of physics steps).
MAX_RECORDING_S = 3600.0


def make_recording(
    source: str,
    fmt: str,
    cmd_t_s: Sequence[float],
    commands: Sequence[Sequence[float]],
    pose_t_s: Sequence[float],
    poses: Sequence[Sequence[float]],
    yaw_rates: Sequence[float] | None = None,
) -> Recording:
    """Validate and sort a recording; times are shifted so that the first pose is at t = 0.
    `yaw_rates` (rad/s), if given, are the odometry's twist yaw rates, one per pose."""
    cmd_t, cmd = np.asarray(cmd_t_s, dtype=float), np.asarray(commands, dtype=float).reshape(-1, 2)
    pose_t, pose = np.asarray(pose_t_s, dtype=float), np.asarray(poses, dtype=float).reshape(-1, 3)
    rates = None if yaw_rates is None else np.asarray(yaw_rates, dtype=float).reshape(-1)
    if rates is not None and (len(rates) != len(pose_t) or not np.all(np.isfinite(rates))):
        raise ReplayError(f"{source}: odometry yaw rates must be finite, one per pose")
    if len(cmd_t) == 0:
        raise ReplayError(f"{source}: no velocity commands")
    if len(pose_t) < 2:
        raise ReplayError(f"{source}: need at least 2 recorded poses, got {len(pose_t)}")
    checks = (("command", np.column_stack([cmd_t, cmd])), ("pose", np.column_stack([pose_t, pose])))
    for name, values in checks:
        if not np.all(np.isfinite(values)):
            raise ReplayError(f"{source}: a {name} holds a non-finite value")
    c_order, p_order = np.argsort(cmd_t, kind="stable"), np.argsort(pose_t, kind="stable")
    t0 = pose_t[p_order[0]]
    span_s = pose_t[p_order[-1]] - t0
    if span_s <= 0:
        raise ReplayError(f"{source}: the recorded poses span no time")
    if span_s > MAX_RECORDING_S:
        raise ReplayError(
            f"{source}: the recorded poses span {span_s:.4g} s; at most {MAX_RECORDING_S:g} s can be replayed"
        )
    return Recording(
        source,
        fmt,
        cmd_t[c_order] - t0,
        cmd[c_order],
        pose_t[p_order] - t0,
        pose[p_order],
        None if rates is None else rates[p_order],
    )


def _float_cell(row: dict[str, str], column: str, line: int, source: str) -> float | None:
    text = (row.get(column) or "").strip()
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        raise ReplayError(f"{source}: line {line}: column {column!r} is not a number ({text!r})") from None


def read_csv(path: Path) -> Recording:
    """A CSV recording with columns t (s), v (m/s), omega (rad/s), x (m), y (m), theta (rad)."""
    source = str(path)
    try:
        with path.open(newline="") as handle:
            reader = csv.DictReader(handle)
            missing = [c for c in CSV_COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                need = ",".join(CSV_COLUMNS)
                raise ReplayError(
                    f"{source}: missing CSV column(s) {', '.join(missing)} (header needs {need})"
                )
            cmd_t, cmds, pose_t, poses = [], [], [], []
            for line, row in enumerate(reader, start=2):
                t, v, w, x, y, th = (_float_cell(row, c, line, source) for c in CSV_COLUMNS)
                if t is None:
                    raise ReplayError(f"{source}: line {line}: no time t")
                if v is not None and w is not None:
                    cmd_t.append(t)
                    cmds.append((v, w))
                if x is not None and y is not None and th is not None:
                    pose_t.append(t)
                    poses.append((x, y, th))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ReplayError(f"{source}: cannot read CSV ({exc})") from None
    return make_recording(source, "csv", cmd_t, cmds, pose_t, poses)


def _yaw(q: object) -> float:
    """Yaw (rad) of a geometry_msgs/Quaternion."""
    x, y, z, w = q.x, q.y, q.z, q.w  # type: ignore[attr-defined]
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _topic_connections(reader: object, source: str, topic: str, types: Sequence[str]) -> list:
    topics = reader.topics  # type: ignore[attr-defined]
    if topic not in topics:
        have = ", ".join(sorted(topics)) or "none"
        raise ReplayError(f"{source}: no topic {topic!r} in the bag (topics: {have})")
    connections = [c for c in reader.connections if c.topic == topic]  # type: ignore[attr-defined]
    bad = sorted({c.msgtype for c in connections} - set(types))
    if bad:
        raise ReplayError(f"{source}: topic {topic!r} has type {bad[0]}, expected one of {', '.join(types)}")
    return connections


def _read_bag_messages(path: Path, source: str, cmd_topic: str, odom_topic: str) -> Recording:
    AnyReader = require("rosbags.highlevel", "ros2", "replaying a ROS bag").AnyReader  # noqa: N806

    cmd_t, cmds, pose_t, poses, yaw_rates = [], [], [], [], []
    with AnyReader([path]) as reader:
        fmt = "ros2" if reader.is2 else "ros1"
        cmd_conns = _topic_connections(reader, source, cmd_topic, TWIST_TYPES)
        odom_conns = _topic_connections(reader, source, odom_topic, (ODOMETRY_TYPE,))
        t0_ns = None
        for conn, stamp_ns, raw in reader.messages(connections=cmd_conns + odom_conns):
            t0_ns = stamp_ns if t0_ns is None else t0_ns
            t_s = (stamp_ns - t0_ns) * 1e-9
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == cmd_topic:
                twist = getattr(msg, "twist", msg)
                cmd_t.append(t_s)
                cmds.append((twist.linear.x, twist.angular.z))
            else:
                pose = msg.pose.pose
                pose_t.append(t_s)
                poses.append((pose.position.x, pose.position.y, _yaw(pose.orientation)))
                yaw_rates.append(msg.twist.twist.angular.z)
    if not cmds:
        raise ReplayError(f"{source}: no messages on {cmd_topic!r}")
    if not poses:
        raise ReplayError(f"{source}: no messages on {odom_topic!r}")
    return make_recording(source, fmt, cmd_t, cmds, pose_t, poses, yaw_rates)


def read_bag(path: Path, cmd_topic: str = "/cmd_vel", odom_topic: str = "/odometry/filtered") -> Recording:
    """Commands and odometry from a ROS 1 bag file or a ROS 2 bag directory (or a storage file
    inside one)."""
    source = str(path)
    if path.is_file() and path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").exists():
        path = path.parent
    if path.is_dir() and not (path / "metadata.yaml").exists():
        raise ReplayError(f"{source}: a directory without metadata.yaml is not a ROS 2 bag")
    try:
        return _read_bag_messages(path, source, cmd_topic, odom_topic)
    except ReplayError:
        raise
    except Exception as exc:  # any failure of the bag reader means a malformed bag
        detail = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ReplayError(f"{source}: not a readable ROS bag ({detail})") from None


def load_recording(
    path: Path, cmd_topic: str = "/cmd_vel", odom_topic: str = "/odometry/filtered"
) -> Recording:
    """A recording from a .csv file, a ROS 1 .bag file or a ROS 2 bag directory."""
    if not path.exists():
        raise ReplayError(f"{path}: no such file or directory")
    if path.is_file() and path.suffix.lower() == ".csv":
        return read_csv(path)
    if path.is_dir() or path.suffix in (".bag", ".db3", ".mcap"):
        return read_bag(path, cmd_topic, odom_topic)
    raise ReplayError(f"{path}: expected a .bag file, a ROS 2 bag directory or a .csv file")


# --------------------------------------------------------------------------------------------
# divergence


@dataclass(frozen=True)
class Divergence:
    """Simulated versus recorded trajectory at the recorded pose times."""

    ate_rmse_m: float  # RMSE of the position error (m)
    ate_max_m: float  # largest position error (m)
    final_error_m: float  # position error at the last recorded pose (m)
    final_heading_error_rad: float  # |wrapped yaw difference| at the last recorded pose (rad)
    path_length_m: float  # recorded path length (m)
    drift_per_m: float | None  # final_error_m / path_length_m; None below 1 cm of path

    def summary(self) -> dict[str, float | None]:
        return asdict(self)

    def line(self) -> str:
        drift = "n/a" if self.drift_per_m is None else f"{100 * self.drift_per_m:.2f} %"
        return (
            f"ATE RMSE {self.ate_rmse_m:.4f} m, max {self.ate_max_m:.4f} m, final {self.final_error_m:.4f} m "
            f"over {self.path_length_m:.2f} m (drift {drift} of distance travelled)"
        )


def divergence(recorded: np.ndarray, simulated: np.ndarray, path_length_m: float) -> Divergence:
    """Compare two (m, 3) pose arrays sampled at the same times."""
    error = np.hypot(*(simulated[:, :2] - recorded[:, :2]).T)
    final = float(error[-1])
    return Divergence(
        ate_rmse_m=float(np.sqrt(np.mean(error**2))),
        ate_max_m=float(np.max(error)),
        final_error_m=final,
        final_heading_error_rad=abs(float(wrap_angle(simulated[-1, 2] - recorded[-1, 2]))),
        path_length_m=path_length_m,
        drift_per_m=final / path_length_m if path_length_m >= 0.01 else None,
    )


@dataclass(frozen=True)
class ReplayRun:
    """One simulated replay of a recording."""

    params: SimParams
    sim_poses: np.ndarray = field(repr=False)  # (m, 3) simulated poses at the recorded pose times
    divergence: Divergence

    def position_error_m(self, recording: Recording) -> np.ndarray:
        return np.hypot(*(self.sim_poses[:, :2] - recording.poses[:, :2]).T)


def replay(recording: Recording, params: SimParams | None = None) -> ReplayRun:
    """Simulate the recording's commands with `params` and measure the divergence."""
    params = params or SimParams()
    track = simulate_commands(
        recording.cmd_t_s,
        recording.commands,
        recording.duration_s,
        recording.start,
        world=params.world(),
        drive=params.drive(),
        ground=params.ground(),
    )
    sim_poses = track.poses_at(recording.pose_t_s)
    return ReplayRun(params, sim_poses, divergence(recording.poses, sim_poses, recording.path_length_m()))


# --------------------------------------------------------------------------------------------
# yaw-rate lag of the recording


@dataclass(frozen=True)
class YawFit:
    """The recording's yaw-rate lag (husky_sim.sim.yaw_response) and how it was measured."""

    response: YawResponse
    rms_error_radps: float  # rms of simulated lag - recorded yaw rate (rad/s)
    source: str  # "odometry twist" or "differentiated yaw"
    samples: int  # recorded yaw-rate samples fitted

    def summary(self) -> dict[str, object]:
        return {**asdict(self.response), **{k: v for k, v in asdict(self).items() if k != "response"}}

    def line(self) -> str:
        r = self.response
        return (
            f"yaw-rate lag of the recording ({self.samples} samples, yaw rate from the {self.source}): "
            f"gain {r.gain:.3f}, time constant {r.time_constant_s:.3f} s, rms error "
            f"{self.rms_error_radps:.4f} rad/s"
        )


def recorded_yaw_rate(recording: Recording) -> tuple[np.ndarray, np.ndarray, str]:
    """Times (s, strictly increasing), recorded body yaw rate (rad/s) and where it came from: the
    odometry twist when the recording has one that is not all zeros (a recorder that leaves the
    twist empty), else the central difference of the unwrapped recorded yaw."""
    keep = np.concatenate([[True], np.diff(recording.pose_t_s) > 0])
    t = recording.pose_t_s[keep]
    if recording.yaw_rates is not None and np.any(recording.yaw_rates[keep] != 0):
        return t, recording.yaw_rates[keep], "odometry twist"
    return t, np.gradient(np.unwrap(recording.poses[keep, 2]), t), "differentiated yaw"


def applied_yaw_rate(recording: Recording, t_s: np.ndarray, params: SimParams) -> np.ndarray:
    """The recorded commands held, through the drive's velocity and acceleration limits at the
    physics rate (as the simulation applies them), averaged over each [t_s[k], t_s[k+1]) (rad/s)."""
    dt_s = 1.0 / params.physics_hz
    fine_t = np.arange(math.ceil(t_s[-1] / dt_s - 1e-9) + 1) * dt_s
    drive = SkidSteerDrive(params.drive(), 1.0, 1.0)  # only limit() is used: no wheel geometry
    held = held_commands(recording.cmd_t_s, recording.commands, fine_t)
    applied = np.array([drive.limit(command, dt_s)[1] for command in held])
    return interval_means(fine_t, applied, t_s)


def fit_recording_yaw(recording: Recording, params: SimParams | None = None) -> YawFit:
    """Fit the yaw-rate lag to the recording: applied (limited) commanded yaw rate against the
    recorded yaw rate, at the recorded pose times. ValueError when the recording never turns."""
    params = params or SimParams()
    t, measured, source = recorded_yaw_rate(recording)
    response, rms_error = fit_yaw_response(t, applied_yaw_rate(recording, t, params), measured)
    return YawFit(response, rms_error, source, len(t))


# --------------------------------------------------------------------------------------------
# outputs


def summary_dict(
    recording: Recording, runs: dict[str, ReplayRun], inputs: dict[str, object], yaw: YawFit | None = None
) -> dict[str, object]:
    """The JSON summary: inputs, the recording's extent, each run's parameters and divergence, and
    the recording's yaw-rate lag (`yaw_response`, null when the recording never turns)."""
    return {
        "source": recording.source,
        **inputs,
        "commands": len(recording.commands),
        "poses": len(recording.poses),
        "duration_s": recording.duration_s,
        "path_length_m": recording.path_length_m(),
        "runs": {name: {"params": asdict(r.params), **r.divergence.summary()} for name, r in runs.items()},
        "yaw_response": None if yaw is None else yaw.summary(),
    }


def plot_replay(recording: Recording, runs: dict[str, ReplayRun], path: Path) -> None:
    """PNG: recorded versus simulated xy (m), and position error (m) over time (s)."""
    from matplotlib.figure import Figure  # Figure.savefig renders with Agg; no pyplot, no display

    fig = Figure(figsize=(11.0, 4.5), layout="constrained")
    ax_xy, ax_err = fig.subplots(1, 2, width_ratios=(1.2, 1.0))
    ax_xy.plot(recording.poses[:, 0], recording.poses[:, 1], color="black", lw=2.0, label="recorded")
    ax_xy.plot(*recording.poses[0, :2], "o", color="black", label="start")
    for (name, run), style in zip(runs.items(), ("-", "--", ":"), strict=False):
        m, mu = run.params.wheel_separation_multiplier, run.params.ground_friction
        label = f"{name}: multiplier {m:.4g}, ground mu {mu:.4g}"
        ax_xy.plot(run.sim_poses[:, 0], run.sim_poses[:, 1], style, lw=1.5, label=label)
        ax_err.plot(recording.pose_t_s, run.position_error_m(recording), style, lw=1.5, label=name)
    ax_xy.set(xlabel="x (m)", ylabel="y (m)", title="recorded vs simulated trajectory", aspect="equal")
    ax_xy.legend(fontsize=8)
    ax_err.set(xlabel="time since first pose (s)", ylabel="position error (m)", title="simulated - recorded")
    ax_err.grid(alpha=0.3)
    ax_err.legend(fontsize=8)
    fig.savefig(path, dpi=110)


def run_replay(
    path: Path,
    out_dir: Path,
    *,
    cmd_topic: str = "/cmd_vel",
    odom_topic: str = "/odometry/filtered",
    multiplier: float | None = None,
    ground_friction: float | None = None,
) -> list[str]:
    """The `husky-sim replay` command: replay, measure the recording's yaw-rate lag, write the plot
    and the JSON summary to out_dir, and return the report lines."""
    recording = load_recording(path, cmd_topic, odom_topic)
    params = SimParams()
    if multiplier is not None:
        params = replace(params, wheel_separation_multiplier=multiplier)
    if ground_friction is not None:
        params = replace(params, ground_friction=ground_friction)
    _ = params.world(), params.drive(), params.ground()  # a bad value fails here, before any simulation
    lines = [
        f"{recording.source}: {len(recording.commands)} commands, {len(recording.poses)} poses over "
        f"{recording.duration_s:.2f} s, recorded path {recording.path_length_m():.2f} m"
    ]
    runs = {"replay": replay(recording, params)}
    lines.append(
        f"replay (multiplier {params.wheel_separation_multiplier:g}, ground friction "
        f"{params.ground_friction:g}): {runs['replay'].divergence.line()}"
    )
    yaw = None
    try:
        yaw = fit_recording_yaw(recording, params)
        lines += [yaw.line(), "scenario parameters:"]
        lines += ["  " + line for line in params.scenario_yaml(yaw.response).splitlines()]
    except ValueError as exc:  # a recording that never turns: the lag is not identified
        lines.append(f"yaw-rate lag not identified ({_one_line(exc)})")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        inputs: dict[str, object] = {"format": recording.format}
        if recording.format != "csv":
            inputs.update(cmd_topic=cmd_topic, odom_topic=odom_topic)
        (out_dir / SUMMARY_NAME).write_text(
            json.dumps(summary_dict(recording, runs, inputs, yaw), indent=2) + "\n"
        )
        plot_replay(recording, runs, out_dir / PLOT_NAME)
    except OSError as exc:
        raise ReplayError(f"{out_dir}: cannot write the outputs ({exc})") from None
    lines.append(f"wrote {out_dir / SUMMARY_NAME} and {out_dir / PLOT_NAME}")
    return lines


def _one_line(exc: Exception) -> str:
    return " ".join(str(exc).split())
