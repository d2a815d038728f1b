"""How the simulated Husky answers a held command: steady forward speed and yaw rate, their ratios to
what the wheels imply, the yaw rate's rise times and the motor current. The same measures as those
taken of the real recordings (husky_sim.calibration.recordings), so the two compare directly.

A command is held from rest for `hold_s`; "steady" is the mean over the second half of the hold.
The ratios divide by what the simulated wheels' own speeds imply, with the URDF's wheel radius and
track: yaw ratio = yaw rate / (r (w_R - w_L) / B), forward ratio = speed / (r (w_R + w_L) / 2).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from husky_sim.calibration.recordings import MIN_RATIO_SPEED_MPS, MIN_RATIO_YAW_RADPS, rise_times
from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.sim.drive import DriveConfig
from husky_sim.sim.ground import Ground
from husky_sim.sim.open_loop import SimTrack, simulate_commands
from husky_sim.sim.robot_description import load_robot
from husky_sim.sim.world import WorldConfig

#: Hold of each command from rest (s): the real recordings hold each command for 6 s.
HOLD_S = 6.0


@dataclass(frozen=True)
class ResponseRow:
    """One held command's answer (the JSON keys of `husky-sim drive-response --json`)."""

    v_cmd: float  # commanded forward speed (m/s)
    w_cmd: float  # commanded yaw rate (rad/s)
    v: float  # steady forward speed (m/s)
    w: float  # steady yaw rate (rad/s)
    v_wheels: float  # forward speed the wheels imply (m/s)
    w_wheels: float  # yaw rate the wheels imply (rad/s)
    yaw_ratio: float | None  # w / w_wheels
    forward_ratio: float | None  # v / v_wheels
    t63_yaw_s: float | None  # time to 63 % of the steady yaw rate from the command (s)
    t95_yaw_s: float | None  # ... to 95 % (s)
    current_a: float  # steady motor current, mean of the two sides (A)

    def as_dict(self) -> dict[str, float | None]:
        return asdict(self)


def ratio(numerator: float, denominator: float, floor: float) -> float | None:
    """numerator / denominator, None when |denominator| < floor."""
    return numerator / denominator if abs(denominator) >= floor else None


def implied_body_velocity(wheel_speeds: np.ndarray, robot: str = DEFAULT_ROBOT) -> tuple[float, float]:
    """(v m/s, w rad/s) that wheel speeds (rad/s; left joints, then right) imply with the robot's
    URDF wheel radius and track."""
    geometry = load_robot(robot).geometry
    speeds = np.asarray(wheel_speeds, dtype=float)
    half = speeds.shape[-1] // 2
    left, right = float(np.mean(speeds[..., :half])), float(np.mean(speeds[..., half:]))
    r, track = geometry.wheel_radius_m, geometry.track_width_m
    return r * (right + left) / 2.0, r * (right - left) / track


def steady_answer(
    track: SimTrack, command: tuple[float, float], steady_from_s: float, robot: str = DEFAULT_ROBOT
) -> ResponseRow:
    """The row of a track of `robot` that held `command` from t = 0, steady from `steady_from_s` (s)."""
    late = track.t_s >= steady_from_s
    v, w = (float(x) for x in np.mean(track.body_velocity[late], axis=0))
    v_wheels, w_wheels = implied_body_velocity(np.mean(track.wheel_speeds[late], axis=0), robot)
    times = rise_times(track.t_s, track.body_velocity[:, 1], 0.0, w) if abs(w) > 1e-3 else None
    t63, t95 = (None, None) if times is None else (times.t63_s, times.t95_s)
    return ResponseRow(
        v_cmd=float(command[0]),
        w_cmd=float(command[1]),
        v=v,
        w=w,
        v_wheels=v_wheels,
        w_wheels=w_wheels,
        yaw_ratio=ratio(w, w_wheels, MIN_RATIO_YAW_RADPS),
        forward_ratio=ratio(v, v_wheels, MIN_RATIO_SPEED_MPS),
        t63_yaw_s=t63,
        t95_yaw_s=t95,
        current_a=float(np.mean(track.motor_currents[late])),
    )


def drive_response(
    ground: Ground,
    commands: list[tuple[float, float]],
    *,
    payload_kg: float = 0.0,
    hold_s: float = HOLD_S,
    drive: DriveConfig | None = None,
    physics_hz: float = WorldConfig.physics_hz,
    robot: str = DEFAULT_ROBOT,
) -> list[ResponseRow]:
    """Each (v m/s, w rad/s) command held from rest on `ground` for `hold_s` through the robot's
    drive (its limits, the ground's drive response, the motors, the tyres)."""
    if not (0.5 <= hold_s <= 60.0 and math.isfinite(hold_s)):
        raise ValueError(f"hold_s: must be in [0.5, 60] s, got {hold_s}")
    rows = []
    world = WorldConfig(physics_hz=physics_hz, ground_friction=ground.tyre.friction)
    for command in commands:
        track = simulate_commands(
            np.zeros(1),
            np.array([command], dtype=float),
            hold_s,
            (0.0, 0.0, 0.0),
            world=world,
            drive=drive,
            ground=ground,
            payload_kg=payload_kg,
            robot=robot,
        )
        rows.append(steady_answer(track, command, 0.5 * hold_s, robot))
    return rows


def format_table(rows: list[ResponseRow], ground_name: str, payload_kg: float) -> list[str]:
    """The rows as a Markdown table with a title line."""

    def cell(value: float | None, digits: int = 3) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    lines = [
        f"drive response on ground {ground_name!r}, payload {payload_kg:g} kg (each command held from rest; "
        "steady = second half)",
        "",
        "| v_cmd (m/s) | w_cmd (rad/s) | v (m/s) | w (rad/s) | yaw ratio | forward ratio | t63 yaw (s) "
        "| t95 yaw (s) | current (A) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.v_cmd:g} | {r.w_cmd:g} | {r.v:.3f} | {r.w:.3f} | {cell(r.yaw_ratio)} | "
            f"{cell(r.forward_ratio)} | {cell(r.t63_yaw_s, 2)} | {cell(r.t95_yaw_s, 2)} | {r.current_a:.1f} |"
        )
    return lines
