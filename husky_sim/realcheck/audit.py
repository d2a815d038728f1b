"""Configuration audit before a Husky trial: does the scenario's controller set-up fit the robot?

Each finding is pass / warn / fail with the numbers behind it:

- robot radius: the controller's circle against the URDF footprint (0.570 m) and the spec
  sheet's half-diagonal (bumpers included); a circle smaller than the body is a FAIL. For
  husky-cbf: its discs over the footprint and their margin against the sensing noise.
- velocity limits: the NMPC's v / omega bounds against the Husky's published limits
  (husky_sim.sim.specs) and the scenario's drive; a bound the robot cannot reach is a FAIL.
- acceleration: the paper's NMPC has no acceleration constraint, so one control step may ask for
  any change within the bounds; the drive's rate limit then makes the robot lag its plan.
  husky-cbf plans its accelerations within its own bounds, checked against the drive's.
- stopping distance at v_max (reaction over tau, the sensing latency, the ground's drive dead time
  and braking at the drive's deceleration) against the radius margin the plan keeps (husky-cbf
  plans its braking and the dead time and latency it is told of: only what goes beyond those is
  beyond its plan, against its disc margin).
- timing: tau against the p99 of solve times measured here on the scenario's kinematic closed
  loop; a plan that cannot be solved within tau is a FAIL.
- obstacles and sensing: radii, motion and prediction model, noise and latency, stated.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np

from controllers import registry
from controllers.registry import BodyDiscs, PlanProfile
from husky_sim.runs.scenario import Scenario
from husky_sim.sim import specs as specs
from husky_sim.sim.drive import DriveConfig
from husky_sim.sim.kinematic import run_kinematic
from husky_sim.sim.metrics import solver_times

Status = Literal["pass", "warn", "fail"]


@dataclass(frozen=True)
class AuditThresholds:
    """Where pass turns to warn; every tunable of the audit in one place."""

    min_radius_margin_m: float = 0.05  # controller circle beyond the footprint, m
    noise_sigmas: float = 3.0  # margin should cover this many std of pose + obstacle noise
    timing_warn_fraction: float = 0.5  # p99 above this fraction of tau leaves little headroom
    timing_quantile: float = 99.0  # percentile of solve times compared with tau


@dataclass(frozen=True)
class Finding:
    """One audit line: what was checked, the verdict and the numbers."""

    check: str
    status: Status
    detail: str  # the numbers, with units
    values: dict[str, float | int | str | None]

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def spec_sheet_half_diagonal_m(scenario: Scenario) -> float:
    """Half the diagonal of the robot's spec-sheet outline (the Husky's 990 x 670 mm, bumpers
    included), m."""
    sheet = _published(scenario).spec_sheet
    return 0.5 * math.hypot(sheet.length_m, sheet.width_m)


def _published(scenario: Scenario) -> specs.RobotSpecs:
    """The published figures of the scenario's robot (its specs.yaml)."""
    return scenario.robot.description().specs


def drive_config(scenario: Scenario) -> DriveConfig:
    return scenario.drive_config()


def radius_margin_m(scenario: Scenario) -> float:
    """Controller circle radius minus the URDF footprint radius, m (negative: smaller than the body)."""
    return scenario.robot.radius() - scenario.robot.description().geometry.footprint_radius_m


def needed_margin_m(scenario: Scenario, t: AuditThresholds) -> float:
    """The margin (m) a robot's outline must keep: the larger of the minimum and the sensing noise
    (t.noise_sigmas sigma of pose plus obstacle position noise)."""
    s = scenario.sensing
    return max(t.min_radius_margin_m, t.noise_sigmas * math.hypot(s.pose_xy_std_m, s.obstacle_xy_std_m))


def _thin_margin(text: str, needed: float, t: AuditThresholds, values: dict[str, object]) -> Finding:
    return Finding(
        "robot radius",
        "warn",
        f"{text}: below the {needed:.3f} m margin (max of {t.min_radius_margin_m:.3f} m and "
        f"{t.noise_sigmas:g} sigma of pose + obstacle noise)",
        values,
    )


def check_robot_radius(scenario: Scenario, t: AuditThresholds) -> Finding:
    r = scenario.robot.radius()
    footprint = scenario.robot.description().geometry.footprint_radius_m
    outline = spec_sheet_half_diagonal_m(scenario)
    title, sheet = scenario.robot.description().title, _published(scenario).spec_sheet
    needed = needed_margin_m(scenario, t)
    margin = r - footprint
    values = {
        "robot_radius_m": r,
        "footprint_radius_m": footprint,
        "margin_m": margin,
        "needed_margin_m": needed,
    }
    text = f"controller radius {r:.3f} m vs URDF footprint {footprint:.3f} m (margin {margin:+.3f} m)"
    if margin < 0:
        return Finding(
            "robot radius",
            "fail",
            f"{text}: the controller's circle is smaller than the {title}; constraints satisfied can "
            "still mean contact",
            values,
        )
    if margin < needed:
        return _thin_margin(text, needed, t, values)
    if r < outline:
        return Finding(
            "robot radius",
            "warn",
            f"{text}: covers the URDF but not the spec sheet's {1000 * sheet.length_m:.0f} x "
            f"{1000 * sheet.width_m:.0f} mm outline "
            f"(half-diagonal {outline:.3f} m, bumpers/accessories)",
            values,
        )
    return Finding("robot radius", "pass", f"{text}, >= needed {needed:.3f} m", values)


def check_velocity_limits(scenario: Scenario, omega_max_radps: float | None = None) -> Finding:
    """The plan's v and omega bounds against the robot's; `omega_max_radps` is the controller's
    own yaw-rate bound where it is not the scenario's (husky-cbf commands up to the drive's)."""
    c, drive = scenario.controller, drive_config(scenario)
    omega_max = c.omega_max_radps if omega_max_radps is None else omega_max_radps
    published = _published(scenario)
    v_pub = published.spec_sheet.max_speed_mps  # [MANUAL] (the Husky's: 1.0 m/s, [CONTROL] agrees)
    w_pub = published.ros1_diff_drive.angular_max_velocity_radps  # [CONTROL] ROS 1
    w_ros2 = published.ros2_diff_drive.angular_max_velocity_radps
    title = scenario.robot.description().title
    v_limit, w_limit = min(v_pub, drive.max_linear_mps), min(w_pub, drive.max_angular_radps)
    v_abs = max(c.v_max_mps, -c.v_min_mps)
    values = {
        "v_min_mps": c.v_min_mps,
        "v_max_mps": c.v_max_mps,
        "omega_max_radps": omega_max,
        "published_v_mps": v_pub,
        "published_omega_radps": w_pub,
        "drive_v_mps": drive.max_linear_mps,
        "drive_omega_radps": drive.max_angular_radps,
    }
    text = (
        f"NMPC v in [{c.v_min_mps:g}, {c.v_max_mps:g}] m/s, |omega| <= {omega_max:.3f} rad/s; "
        f"{title} {v_pub:g} m/s, {w_pub:g} rad/s (ROS 1; ROS 2: {w_ros2:g} rad/s); "
        f"drive {drive.max_linear_mps:g} m/s, {drive.max_angular_radps:g} rad/s"
    )
    if v_abs > v_limit + 1e-9 or omega_max > w_limit + 1e-9:
        return Finding(
            "velocity limits", "fail", f"{text}: the plan commands speeds the robot cannot reach", values
        )
    if drive.max_linear_mps > v_pub + 1e-9 or drive.max_angular_radps > w_pub + 1e-9:
        return Finding(
            "velocity limits", "warn", f"{text}: the simulated drive exceeds the real robot", values
        )
    if omega_max > w_ros2 + 1e-9:
        return Finding("velocity limits", "warn", f"{text}: above the ROS 2 driver's angular limit", values)
    return Finding("velocity limits", "pass", text, values)


def check_acceleration(scenario: Scenario) -> Finding:
    c, drive, tau = scenario.controller, drive_config(scenario), scenario.tau_s
    dv = c.v_max_mps - c.v_min_mps  # worst one-step change of the linear command, m/s
    dw = 2.0 * c.omega_max_radps  # rad/s
    a_implied, alpha_implied = dv / tau, dw / tau
    ros1, ros2 = _published(scenario).ros1_diff_drive, _published(scenario).ros2_diff_drive
    a_pub, alpha_pub = ros1.linear_max_acceleration_mps2, ros1.angular_max_acceleration_radps2
    a_drive, alpha_drive = drive.max_linear_accel_mps2, drive.max_angular_accel_radps2
    lag_m = c.v_max_mps**2 / (2.0 * a_drive)  # distance the robot trails a plan that jumps 0 -> v_max
    values = {
        "implied_linear_accel_mps2": a_implied,
        "implied_angular_accel_radps2": alpha_implied,
        "drive_linear_accel_mps2": a_drive,
        "drive_angular_accel_radps2": alpha_drive,
        "published_linear_accel_mps2": a_pub,
        "published_angular_accel_radps2": alpha_pub,
        "steps_to_reach_v_max": math.ceil(c.v_max_mps / (a_drive * tau) - 1e-9),
        "plan_lag_m": lag_m,
    }
    text = (
        f"worst one-step change {dv:g} m/s, {dw:.2f} rad/s in tau {tau:g} s = {a_implied:.1f} m/s^2, "
        f"{alpha_implied:.1f} rad/s^2 vs drive {a_drive:g} m/s^2, {alpha_drive:g} rad/s^2 "
        f"(published ROS 1 {a_pub:g} / {alpha_pub:g}, ROS 2 {ros2.linear_max_acceleration_mps2:g} "
        f"/ {ros2.angular_max_acceleration_radps2:g})"
    )
    if a_drive > a_pub + 1e-9 or alpha_drive > alpha_pub + 1e-9:
        return Finding(
            "acceleration", "warn", f"{text}: the simulated drive accelerates harder than the robot", values
        )
    if a_implied > a_drive or alpha_implied > alpha_drive:
        return Finding(
            "acceleration",
            "warn",
            f"{text}: the NMPC has no acceleration constraint; the drive needs "
            f"{values['steps_to_reach_v_max']} steps to reach v_max and the robot trails such a "
            f"plan by up to {lag_m:.3f} m",
            values,
        )
    return Finding("acceleration", "pass", text, values)


# -- a controller that models its body as discs, its accelerations and its braking (husky-cbf) ------
def check_body_discs(scenario: Scenario, name: str, body: BodyDiscs, t: AuditThresholds) -> Finding:
    """The discs that cover the URDF footprint in the controller's model and their margin,
    against the noise."""
    needed = needed_margin_m(scenario, t)
    length, width = (2 * h for h in body.footprint_half_extents_m)
    values = {
        "discs": body.count,
        "disc_radius_m": body.radius_m,
        "footprint_m": [length, width],
        "margin_m": body.margin_m,
        "needed_margin_m": needed,
    }
    text = (
        f"{name}: {body.count} discs of {body.radius_m:.3f} m along the body cover the URDF "
        f"footprint {length:.3f} x {width:.3f} m, each kept {body.margin_m:.3f} m off obstacles"
    )
    if body.margin_m < needed:
        return _thin_margin(text, needed, t, values)
    return Finding("robot radius", "pass", f"{text}, >= needed {needed:.3f} m", values)


def check_planned_acceleration(scenario: Scenario, name: str, accel: tuple[float, float]) -> Finding:
    """The accelerations (m/s^2, rad/s^2) the controller's plans are bounded to in its model,
    against the drive's."""
    drive = drive_config(scenario)
    linear, angular = accel
    ros1 = _published(scenario).ros1_diff_drive
    a_pub, alpha_pub = ros1.linear_max_acceleration_mps2, ros1.angular_max_acceleration_radps2
    values = {
        "planned_linear_accel_mps2": linear,
        "planned_angular_accel_radps2": angular,
        "drive_linear_accel_mps2": drive.max_linear_accel_mps2,
        "drive_angular_accel_radps2": drive.max_angular_accel_radps2,
        "published_linear_accel_mps2": a_pub,
        "published_angular_accel_radps2": alpha_pub,
    }
    text = (
        f"{name} plans within {linear:g} m/s^2, {angular:g} rad/s^2 vs drive "
        f"{drive.max_linear_accel_mps2:g} m/s^2, {drive.max_angular_accel_radps2:g} rad/s^2 "
        f"(published ROS 1 {a_pub:g} / {alpha_pub:g})"
    )
    if linear > drive.max_linear_accel_mps2 + 1e-9 or angular > drive.max_angular_accel_radps2 + 1e-9:
        return Finding(
            "acceleration", "warn", f"{text}: it plans accelerations the drive cannot make", values
        )
    if drive.max_linear_accel_mps2 > a_pub + 1e-9 or drive.max_angular_accel_radps2 > alpha_pub + 1e-9:
        return Finding(
            "acceleration", "warn", f"{text}: the simulated drive accelerates harder than the robot", values
        )
    return Finding("acceleration", "pass", text, values)


def check_planned_stopping(scenario: Scenario, name: str, plan: PlanProfile) -> Finding:
    """Braking is in the controller's plan (husky-cbf keeps v^2 / 2a free at the horizon's end),
    and so are the drive's dead time and the sensing latency it is told of; any latency or dead
    time beyond those can carry the robot past a planned stop."""
    assert plan.body is not None and plan.planned_dead_time_s is not None
    margin = plan.body.margin_m
    reaction, latency, braking = stopping_distance_m(scenario)
    dead_time = dead_time_m(scenario)
    planned_dead_time = scenario.controller.v_max_mps * plan.planned_dead_time_s
    planned_latency = scenario.controller.v_max_mps * plan.planned_latency_s
    unplanned = max(latency - planned_latency, 0.0) + max(dead_time - planned_dead_time, 0.0)
    values = {
        "reaction_m": reaction,
        "latency_m": latency,
        "dead_time_m": dead_time,
        "planned_dead_time_m": planned_dead_time,
        "planned_latency_m": planned_latency,
        "braking_m": braking,
        "stopping_m": reaction + latency + dead_time + braking,
        "unplanned_overrun_m": unplanned,
        "margin_m": margin,
    }
    text = (
        f"stop from v_max {scenario.controller.v_max_mps:g} m/s: {values['stopping_m']:.3f} m "
        f"({reaction:.3f} m over tau + {latency:.3f} m latency + {dead_time:.3f} m drive dead time + "
        f"{braking:.3f} m braking; {name} plans the braking, {planned_dead_time:.3f} m of dead "
        f"time and {planned_latency:.3f} m of latency); beyond the plan {unplanned:.3f} m vs disc "
        f"margin {margin:.3f} m"
    )
    if unplanned > margin:
        return Finding(
            "stopping distance",
            "warn",
            f"{text}: the sensing latency and the drive's dead time carry the robot past a planned "
            "stop by more than its margin",
            values,
        )
    return Finding("stopping distance", "pass", text, values)


def stopping_distance_m(scenario: Scenario) -> tuple[float, float, float]:
    """Distances (m) to stop from v_max: (reaction over one control period v tau, which the plan
    knows of; latency v tau k, which the paper's does not; braking v^2 / (2 a_drive), which it
    treats as instant)."""
    v, drive = scenario.controller.v_max_mps, drive_config(scenario)
    reaction = v * scenario.tau_s
    latency = v * scenario.tau_s * scenario.sensing.latency_steps
    return reaction, latency, v**2 / (2.0 * drive.max_linear_accel_mps2)


def dead_time_m(scenario: Scenario) -> float:
    """Distance (m) the robot covers at v_max during its ground's drive dead time (a calibrated
    ground's is the real drive's: 0.34 s on wet grass), before it acts on a command to stop."""
    return scenario.controller.v_max_mps * scenario.ground_config().drive.command_delay_s


def check_stopping_distance(scenario: Scenario) -> Finding:
    reaction, latency, braking = stopping_distance_m(scenario)
    dead_time = dead_time_m(scenario)
    overrun, margin = latency + dead_time + braking, radius_margin_m(scenario)
    values = {
        "reaction_m": reaction,
        "latency_m": latency,
        "dead_time_m": dead_time,
        "braking_m": braking,
        "stopping_m": reaction + latency + dead_time + braking,
        "unplanned_overrun_m": overrun,
        "radius_margin_m": margin,
    }
    text = (
        f"stop from v_max {scenario.controller.v_max_mps:g} m/s: {values['stopping_m']:.3f} m "
        f"({reaction:.3f} m over tau + {latency:.3f} m latency + {dead_time:.3f} m drive dead time + "
        f"{braking:.3f} m braking); beyond the plan {overrun:.3f} m vs radius margin {margin:+.3f} m"
    )
    if overrun > margin:
        return Finding(
            "stopping distance",
            "warn",
            f"{text}: the plan assumes an instant stop; at full speed the robot overruns a planned "
            "stop (latency, the drive's dead time, braking) by more than its margin",
            values,
        )
    return Finding("stopping distance", "pass", text, values)


def measure_solve_times(
    scenario: Scenario, controller: str, horizon: int | None = None, solves: int = 100
) -> np.ndarray:
    """Wall times (s) of `solves` NMPC solves on the scenario's kinematic closed loop on this
    machine; the loop restarts from the start pose when a set-point is reached early. Steps
    that ran no solver (their problems answered before, bit for bit) are not counted."""
    scenario = scenario.with_overrides(horizon=horizon)
    nmpc = scenario.make_controller(controller)
    problem = scenario.kinematic_problem(allow_waypoints=True)
    times: list[float] = []
    while len(times) < solves:
        remaining = solves - len(times)
        episode = run_kinematic(
            nmpc,
            problem.start,
            problem.reference,
            problem.obstacles,
            scenario.tau_s,
            remaining * scenario.tau_s,
            problem.robot_radius_m,
        )
        times.extend(solver_times(episode.solve_time_s, episode.repeated).tolist())
    return np.array(times[:solves])


def check_timing(tau_s: float, solve_times_s: Sequence[float], t: AuditThresholds) -> Finding:
    """tau against the measured solve-time quantile: above tau FAIL, above a fraction WARN."""
    ms = 1000.0 * np.asarray(solve_times_s, dtype=float)
    q = float(np.percentile(ms, t.timing_quantile))
    tau_ms = 1000.0 * tau_s
    over = int(np.sum(ms > tau_ms))
    values = {
        "tau_ms": tau_ms,
        "solve_p99_ms": q,
        "solve_median_ms": float(np.median(ms)),
        "solve_max_ms": float(np.max(ms)),
        "solves": int(ms.size),
        "solves_over_tau": over,
    }
    text = (
        f"tau {tau_ms:g} ms vs solve p{t.timing_quantile:g} {q:.2f} ms "
        f"(median {values['solve_median_ms']:.2f}, "
        f"max {values['solve_max_ms']:.2f} ms, {over}/{ms.size} over tau; measured on this machine)"
    )
    if q > tau_ms:
        return Finding("timing", "fail", f"{text}: the plan cannot be solved within tau", values)
    if q > t.timing_warn_fraction * tau_ms or over:
        return Finding("timing", "warn", f"{text}: little headroom for sensing and communication", values)
    return Finding("timing", "pass", text, values)


def check_obstacles(scenario: Scenario) -> Finding:
    obstacles = scenario.obstacle_specs()
    prediction = scenario.controller.obstacle_prediction
    moving = [o for o in obstacles if o.moving]
    speeds = [float(np.hypot(*o.state_at(0.0)[1])) for o in moving]
    radii = [o.radius_m for o in obstacles]
    values = {
        "count": len(obstacles),
        "moving": len(moving),
        "radius_min_m": min(radii) if radii else None,
        "radius_max_m": max(radii) if radii else None,
        "speed_max_mps": max(speeds) if speeds else None,
        "prediction": prediction,
    }
    if not obstacles:
        return Finding("obstacles", "pass", "no obstacles", values)
    text = (
        f"{len(obstacles)} cylinders, radius {min(radii):.2f}-{max(radii):.2f} m as given (no inflation), "
        f"{len(moving)} moving"
        + (f" up to {max(speeds):.2f} m/s" if speeds else "")
        + f"; prediction {prediction}; velocities told to the controller exactly unless "
        f"sensing.obstacle_velocity_scale (now {scenario.sensing.obstacle_velocity_scale:g})"
    )
    if moving and prediction == "frozen":
        return Finding("obstacles", "warn", f"{text}: the plan ignores the obstacles' motion", values)
    return Finding("obstacles", "pass", text, values)


def check_sensing(scenario: Scenario) -> Finding:
    s = scenario.sensing
    values = dict(s.model_dump())
    text = (
        f"pose noise {s.pose_xy_std_m:g} m / {s.pose_yaw_std_rad:g} rad, obstacle noise "
        f"{s.obstacle_xy_std_m:g} m, latency {s.latency_steps} steps "
        f"({s.latency_steps * scenario.tau_s:g} s), obstacle velocity scale {s.obstacle_velocity_scale:g}"
    )
    ideal = (
        s.pose_xy_std_m == 0
        and s.pose_yaw_std_rad == 0
        and s.obstacle_xy_std_m == 0
        and s.latency_steps == 0
        and s.obstacle_velocity_scale == 1
    )
    if ideal:
        return Finding("sensing", "warn", f"{text}: ideal sensing; the robustness sweep perturbs it", values)
    return Finding("sensing", "pass", text, values)


def audit(
    scenario: Scenario,
    solve_times_s: Sequence[float],
    thresholds: AuditThresholds | None = None,
    controller: str = registry.DEFAULT,
) -> list[Finding]:
    """Every finding for a scenario (its controller already set to the horizon under test), given
    solve times measured for it (measure_solve_times). What the controller's plans promise
    (its registry entry's PlanProfile) decides which checks apply: a body of discs, or the
    scenario's circle; accelerations and braking in its model, or an unconstrained step and an
    instant stop (the paper's unicycle)."""
    t = thresholds or AuditThresholds()
    plan = scenario.plan_profile(controller)
    planned_stop = plan.body is not None and plan.planned_dead_time_s is not None
    return [
        check_robot_radius(scenario, t)
        if plan.body is None
        else check_body_discs(scenario, controller, plan.body, t),
        check_velocity_limits(scenario, plan.omega_cmd_max_radps),
        check_acceleration(scenario)
        if plan.planned_accel is None
        else check_planned_acceleration(scenario, controller, plan.planned_accel),
        check_planned_stopping(scenario, controller, plan)
        if planned_stop
        else check_stopping_distance(scenario),
        check_timing(scenario.tau_s, solve_times_s, t),
        check_obstacles(scenario),
        check_sensing(scenario),
    ]
