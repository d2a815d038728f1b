"""Kinematic closed loop: the controller drives its own unicycle model (RK4 over tau), no physics.

This is the paper's MATLAB-style simulation, kept as a reference point next to the PyBullet runs:
it isolates the controller's behaviour from wheel slip, actuator limits and body geometry. It is
a second plant behind the same loop (husky_sim.sim.rollout) and outcome monitor as the PyBullet
Husky; what differs is said here. Obstacles move at constant velocity and are sensed exactly; the
robot is the controller's circle, and clearance is measured on the circle model at the end of each
step. The paper's rules for this loop: it runs its full time unless the set-point is held (a
collision does not end it; the stuck rule is judged once, at the end, on the last commands), and a
clearance above -KINEMATIC_CONTACT_TOL_M is contact, not collision. The sensing model
(husky_sim.sim.sensing) is not applied: every obstacle is reported visible. The first collision
is classified as the PyBullet plant's first contact (husky_sim.sim.contact), on the circle model:
at the first step end whose clearance is below -KINEMATIC_CONTACT_TOL_M, the nearest circle, the
commanded speed going into that step and the obstacle's constant velocity.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from controllers import Controller, Obstacle, Reference
from controllers.model import step, wrap_angle
from husky_sim.interrupts import RunInterrupted
from husky_sim.sim.contact import Contact, classify
from husky_sim.sim.metrics import count_reversals
from husky_sim.sim.outcomes import OutcomeMonitor, Outcomes
from husky_sim.sim.rollout import control_steps, rollout
from husky_sim.sim.sensing import Measurement

#: Kinematic clearance above -this (m) is contact, not collision: IPOPT meets B = 0 to ~1e-9, and
#: the model the controller plans with is the plant, so its plans are followed exactly.
KINEMATIC_CONTACT_TOL_M = 1e-6


@dataclass(frozen=True)
class KinematicProblem:
    """What a kinematic run needs besides the controller: start (m, m, rad), reference, obstacles
    at t = 0 (constant velocity), the robot's circle (m) and the duration (s)."""

    name: str
    start: tuple[float, float, float]
    reference: Reference
    obstacles: tuple[Obstacle, ...]
    robot_radius_m: float
    duration_s: float


@dataclass
class KinematicEpisode:
    """Per-step record of a kinematic closed-loop run and its headline figures."""

    times_s: np.ndarray  # (K+1,)
    states: np.ndarray  # (K+1, 3)
    controls: np.ndarray  # (K, 2)
    clearance_m: np.ndarray  # (K+1,) min over obstacles of centre distance - radii sum
    min_decay_slack: np.ndarray  # (K,) smallest s_h of each solved plan
    safety_active: np.ndarray  # (K,) active obstacle constraints per step
    solve_time_s: np.ndarray  # (K,)
    repeated: np.ndarray  # (K,) 1 where no solver ran (controllers.backends.repeats)
    fallbacks: int
    reached: bool
    time_to_goal_s: float | None
    statuses: list[str] = field(default_factory=list)
    outcome: str | None = None  # what the outcome monitor decided (None: nothing; final_outcome)

    @property
    def min_clearance_m(self) -> float:
        return float(np.min(self.clearance_m))

    @property
    def collided(self) -> bool:
        return self.min_clearance_m < 0.0

    @property
    def reversals(self) -> int:
        """Times the command switched into reverse (see husky_sim.sim.metrics.count_reversals)."""
        return count_reversals(self.controls[:, 0])[0]

    @property
    def reverse_steps(self) -> int:
        """Control steps commanding reverse."""
        return count_reversals(self.controls[:, 0])[1]

    @property
    def safety_active_steps(self) -> int:
        return int(np.sum(self.safety_active > 0))

    def final_errors(self, reference: Reference) -> tuple[float, float]:
        """Final position (m) and wrapped heading (rad) errors against the reference."""
        ref = reference.state_at(float(self.times_s[-1]))
        pos = float(np.hypot(*(self.states[-1, :2] - ref[:2])))
        return pos, abs(float(wrap_angle(self.states[-1, 2] - ref[2])))


def obstacles_at(obstacles: Sequence[Obstacle], t_s: float) -> list[Obstacle]:
    """Constant-velocity obstacles as seen at time t_s (position advanced, velocity kept)."""
    out = []
    for o in obstacles:
        x, y = o.position_after(t_s)
        out.append(Obstacle(float(x), float(y), o.radius_m, o.vx_mps, o.vy_mps))
    return out


def clearance(position_xy: np.ndarray, obstacles: Sequence[Obstacle], robot_radius_m: float) -> float:
    """Smallest centre distance minus radii sum (m); +inf without obstacles."""
    if not obstacles:
        return float("inf")
    return min(
        float(np.hypot(position_xy[0] - o.x_m, position_xy[1] - o.y_m)) - o.radius_m - robot_radius_m
        for o in obstacles
    )


class KinematicEnvironment:
    """The controller's unicycle as a husky_sim.sim.rollout.Plant: the command is followed exactly
    (RK4 over tau_s, controllers.model.step), the body velocity is the last command, and there are
    no wheels (their speeds are NaN)."""

    def __init__(
        self, start: Sequence[float], obstacles: Sequence[Obstacle], tau_s: float, robot_radius_m: float
    ) -> None:
        self.tau_s = tau_s
        self._obstacles = list(obstacles)
        self._state = np.asarray(start, dtype=float)
        self._command = np.zeros(2)
        self._k = 0  # control steps taken: the time is k * tau_s
        self.footprint_radius_m = robot_radius_m
        self.obstacle_radii_m = np.array([o.radius_m for o in self._obstacles])
        self.initial_clearance_m = clearance(self._state, obstacles_at(self._obstacles, 0.0), robot_radius_m)
        #: the first collision (husky_sim.sim.contact), recorded once; None before it
        self.first_contact: Contact | None = None

    def pose(self) -> np.ndarray:
        return self._state

    def body_velocity(self) -> np.ndarray:
        return self._command

    def wheel_speeds(self) -> np.ndarray:
        return np.full(4, np.nan)

    def motor_currents(self) -> np.ndarray:
        return np.full(2, np.nan)

    def measure(self) -> Measurement:
        """The exact state and every obstacle at the current time (all visible)."""
        obstacles = obstacles_at(self._obstacles, self._k * self.tau_s)
        return Measurement(self._state, obstacles, tuple(range(len(obstacles))))

    def obstacle_centres(self, t_s: float) -> np.ndarray:
        return np.array([o.position_after(t_s) for o in self._obstacles], dtype=float).reshape(-1, 2)

    def advance(
        self, command: np.ndarray, on_physics_step: Callable[[np.ndarray], None] | None = None
    ) -> tuple[np.ndarray, float]:
        """One RK4 step of tau_s; the clearance is the circle model's at the step's end, and the
        first end below -KINEMATIC_CONTACT_TOL_M records `first_contact`."""
        t = self._k * self.tau_s
        yaw = float(self._state[2])
        self._state = step(self._state, command, self.tau_s)
        self._command = command
        self._k += 1
        if on_physics_step is not None:
            on_physics_step(command)
        t_next = t + self.tau_s
        circles = obstacles_at(self._obstacles, t_next)
        gap = clearance(self._state, circles, self.footprint_radius_m)
        if self.first_contact is None and gap < -KINEMATIC_CONTACT_TOL_M:
            gaps = [clearance(self._state, [o], self.footprint_radius_m) for o in circles]
            index = int(np.argmin(gaps))
            v = float(command[0])
            touched = circles[index]
            self.first_contact = classify(
                t_next, index, (v * np.cos(yaw), v * np.sin(yaw)), (touched.vx_mps, touched.vy_mps)
            )
        return command, gap


def run_kinematic(
    controller: Controller,
    start: Sequence[float],
    reference: Reference,
    obstacles: Sequence[Obstacle],
    tau_s: float,
    duration_s: float,
    robot_radius_m: float,
    outcomes: Outcomes | None = None,
) -> KinematicEpisode:
    """Run the closed loop for duration_s (s); a set-point run stops once the goal is held within
    the goal tolerances of `outcomes` (position m, heading rad, for goal_hold_s). A signal raises
    RunInterrupted (a kinematic run has no folder to keep its steps in)."""
    outcomes = replace(outcomes or Outcomes(), stop_on_collision=False, stop_early=True)
    plant = KinematicEnvironment(start, obstacles, tau_s, robot_radius_m)
    monitor = OutcomeMonitor(
        reference, outcomes, tau_s, contact_tolerance_m=KINEMATIC_CONTACT_TOL_M, stuck_at_end=True
    )
    record = rollout(plant, controller, reference, monitor, control_steps(duration_s, tau_s), tau_s)
    if record.interrupted_by is not None:
        raise RunInterrupted(record.interrupted_by)
    rows = record.rows

    def column(name: str) -> np.ndarray:
        return np.array([r[name] for r in rows])

    poses = np.column_stack([column("x_m"), column("y_m"), column("yaw_rad")]).reshape(-1, 3)
    states = np.vstack([poses, record.final_pose])
    return KinematicEpisode(
        times_s=tau_s * np.arange(len(states)),
        states=states,
        controls=np.column_stack([column("v_cmd_mps"), column("omega_cmd_radps")]).reshape(-1, 2),
        clearance_m=np.concatenate([[plant.initial_clearance_m], column("clearance_m")]).astype(float),
        min_decay_slack=column("s_h_min"),
        safety_active=column("safety_active"),
        solve_time_s=column("solve_ms") / 1000.0,
        repeated=column("repeated"),
        fallbacks=int(np.sum(column("fallback") != "none")),
        reached=monitor.goal_held,
        time_to_goal_s=monitor.reached_at if monitor.goal_held else None,
        statuses=[str(r["status"]) for r in rows],
        outcome=monitor.outcome,
    )
