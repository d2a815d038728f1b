"""husky-cbf: the paper's Relax-CBF NMPC-CLF extended with what a Husky's physics needs.

Per control step:
1. the initial state of the extended model, at the instant the drive will act on this step's
   command (delay.py: after the drive's dead time): the pose and body yaw rate predicted over the
   sensing latency and the dead time from the measured pose and the estimated yaw rate (the
   model's prediction corrected by the measured heading change) under the commands already sent,
   and the last command;
2. the reference: the paper's, unless guidance (guidance.py) gives a waypoint: out of the way of a
   mover on a collision course, out of a deadlock (escape.py: the robot made no progress towards
   its target), onto a set-point's line near the goal (straight at the point of a slow
   trajectory, or beside it while a mover is on course to it; at the point, facing across the
   track of a mover on course to it), or along a shortest path when the straight way is blocked
   (backwards, while stepping aside, if that turns less);
3. the nearest obstacles predicted at constant velocity, each inflated by the margin; a mover
   covers its next mover_sweep_s of travel at every step, with a margin growing with that travel;
4. the hard OCP (ocp.py); if IPOPT fails, the same OCP with an exactly penalised obstacle slack
   (a feasible hard plan is its optimum, so this also recovers solves that failed from a poor
   start); if that fails too, again from each of controllers.recovery's guesses; else brake.
Every step reports whether it was guided, penalised (obstacle slack > 0) or recovered.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from controllers.backends import FatropSolver, IpoptSolver, RawSolution
from controllers.husky_cbf.config import HuskyCBFConfig
from controllers.husky_cbf.delay import CommandPipe
from controllers.husky_cbf.escape import Escape
from controllers.husky_cbf.footprint import disc_cover
from controllers.husky_cbf.guidance import (
    Guidance,
    LineApproach,
    MoverEvasion,
    Waypoint,
    inflated_circles,
    nearer_way,
    point_approach,
)
from controllers.husky_cbf.localisation import PoseFilter
from controllers.husky_cbf.model import extended_step
from controllers.husky_cbf.ocp import ExtendedPlan, Layout, pack_parameters, solver_for
from controllers.husky_cbf.safety_filter import SafetyFilter
from controllers.husky_cbf.turn_monitor import TurnMonitor
from controllers.interface import ControlResult
from controllers.model import wrap_angle
from controllers.obstacles import Obstacle, predict_obstacles
from controllers.recovery import recovery_commands
from controllers.references import Reference, SetPoint
from controllers.signals import deliver_after_solve

#: An obstacle constraint residual (m^2) at most this counts as active.
ACTIVE_TOL = 1e-4
#: An obstacle slack (m^2) above this means the plan needed the penalised slack.
SLACK_TOL = 1e-6
#: Weight of the measured heading change in the body yaw-rate estimate (0: model only).
YAW_RATE_CORRECTION = 0.5
#: Tracking: how far (s) past the preview the reference is searched for a point in free space.
TRACKING_SEARCH_S = 5.0


class HuskyCBFController:
    """The `husky-cbf` controller; implements controllers.interface.Controller."""

    def __init__(self, config: HuskyCBFConfig) -> None:
        self.config = config
        base = config.nmpc
        self._hard_problem, self._hard = solver_for(config, base.horizon, config.slots, soft=False)
        self._soft_problem, self._soft = solver_for(config, base.horizon, config.slots, soft=True)
        self._solver_fallbacks: list[str] = []  # this step's reasons the structured solver failed
        self._discs, self._disc_radius = disc_cover(config.footprint, config.disc_excess_m)
        # guidance's and evasion's movers as wide as the NMPC's (_obstacles) at the horizon's middle
        plan_s = config.measurement_delay_s + 0.5 * base.horizon * base.tau_s
        growth_s = 0.5 * config.mover_sweep_s + config.mover_margin_per_m * plan_s
        self._pipe = CommandPipe(config.response, base.tau_s, config.measurement_delay_s)
        #: how far along its track (s) a mover's first NMPC circle is centred (_obstacles): the
        #: drive's dead time plus half the sweep; guidance's circles start there too, for a robot
        #: waiting on a slow reference
        self._mover_lead_s = self._pipe.delay_s + 0.5 * config.mover_sweep_s
        inflation_m = self._disc_radius + config.margin_m
        self._guidance = Guidance(config.guidance, inflation_m, growth_s, self._mover_lead_s)
        self._approach = LineApproach(config.guidance)
        # stepping aside from the robot; the waiting spot and the turn across a track, from its point
        self._evasion, self._waiting, self._bracing = (
            MoverEvasion(config.guidance, inflation_m, growth_s) for _ in range(3)
        )
        footprint = config.footprint
        swing_m = math.hypot(footprint.half_length_m, footprint.half_width_m) - self._disc_radius
        self._escape = Escape(config.escape, base.tau_s, swing_m)
        self._step = extended_step(base.tau_s, config.response)
        #: from now to the instant the first command acts (s): the prediction's span less the latency
        self._plan_start_s = max(self._pipe.delay_s - config.sensing_latency_s, 0.0)
        self._pose_filter = PoseFilter(config.pose_noise, base.tau_s)
        self._turns = TurnMonitor(round(config.weak_turn_window_s / base.tau_s), config.weak_turn_min_rad)
        self._filter = (
            SafetyFilter(
                config.response,
                base.tau_s,
                self._discs,
                self._disc_radius,
                config.mover_accel_bound_mps2,
                config.measurement_delay_s,
            )
            if config.safety_filter
            else None
        )
        self.reset()

    @property
    def tau_s(self) -> float:
        return self.config.nmpc.tau_s

    @property
    def disc_radius_m(self) -> float:
        return self._disc_radius

    def reset(self) -> None:
        self._plan: ExtendedPlan | None = None
        self._pipe.reset()
        self._omega_body = 0.0  # body yaw rate predicted for now (rad/s)
        self._predicted_turn = 0.0  # heading change predicted over the last control step (rad)
        self._predicted_speed = 0.0  # mean body speed predicted over the last control step (m/s)
        self._yaw_prev: float | None = None
        self._guidance.reset()
        self._approach.reset()
        self._evasion.reset()
        self._waiting.reset()
        self._bracing.reset()
        self._escape.reset()
        self._pose_filter.reset()
        self._turns.reset()
        self._hard.reset()
        self._soft.reset()

    # -- per-step preparation -------------------------------------------------------------
    def _measured_turn(self, pose: np.ndarray) -> float | None:
        """The heading change (rad) measured over the last control step; None without one."""
        return None if self._yaw_prev is None else float(wrap_angle(pose[2] - self._yaw_prev))

    def _initial_state(self, pose: np.ndarray, measured_turn: float | None) -> tuple[np.ndarray, float]:
        """The extended state where this step's command takes effect (after the dead time), and
        the body yaw rate estimated now (rad/s)."""
        omega = self._omega_body
        if measured_turn is not None:
            omega += YAW_RATE_CORRECTION * (measured_turn - self._predicted_turn) / self.tau_s
        ahead, omega_ahead = self._pipe.predict_dead_time(pose, omega)
        return np.array([*ahead, *self._pipe.current, omega_ahead]), omega

    def _reference(
        self,
        pose: np.ndarray,
        estimate: np.ndarray,
        speed_mps: float,
        reference: Reference,
        sampled: tuple[np.ndarray, np.ndarray],
        stationary: bool,
        obstacles: Sequence[Obstacle],
        t: float,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """The states and feed-forward (N+1, 3), (N, 2) the OCP tracks, and whether they are a
        guidance waypoint; `sampled` is the reference sampled along the horizon, `estimate` the
        filtered pose on which the set-point approach decides (localisation.PoseFilter)."""
        cfg, base = self.config, self.config.nmpc
        ref_states, ref_controls = sampled
        w = cfg.omega_cmd_max_radps
        ref_controls[:, 1] = np.clip(ref_controls[:, 1] / cfg.response.yaw_gain, -w, w)
        circles = inflated_circles(obstacles, self._guidance.inflation_m, 0.0, pose[:2])
        goal = (
            ref_states[-1] if isinstance(reference, SetPoint) else self._tracking_goal(reference, circles, t)
        )
        # where to go now, in priority: out of a mover's way, out of a deadlock, onto a
        # set-point's line (or at a slow trajectory's point), the goal
        set_point = isinstance(reference, SetPoint)
        slow_trajectory = stationary and not set_point
        now_state, now_control = ref_states[0], ref_controls[0]
        meant = self._meant_velocity(pose, speed_mps, set_point, slow_trajectory, now_state, now_control)
        target = self._evasion.waypoint(pose, meant, obstacles)
        if target is not None or not slow_trajectory:
            self._waiting.reset()
        escape = self._escape_waypoint(
            pose, goal, set_point, slow_trajectory, target is not None, circles, obstacles, t
        )
        if escape is not None:
            target = [escape.x_m, escape.y_m, escape.heading_rad]
            return np.tile(target, (base.horizon + 1, 1)), np.zeros((base.horizon, 2)), True
        if target is None and slow_trajectory:
            g = cfg.guidance
            spot = self._waiting_spot(pose, goal, obstacles)
            if spot is not None:
                goal = np.array([spot.x_m, spot.y_m, goal[2]])
            target = point_approach(pose, goal, g.point_approach_near_m, g.point_approach_far_m)
            if target is None and spot is not None:
                target = Waypoint(spot.x_m, spot.y_m, float(pose[2]), np.array([pose[:2], goal[:2]]))
            across = None if spot is not None else self._heading_across(pose, goal, obstacles)
            if across is not None:
                target = Waypoint(float(goal[0]), float(goal[1]), across, np.array([pose[:2], goal[:2]]))
        elif target is None and stationary:
            target = self._approach.waypoint(estimate, goal, circles)
        if target is not None:
            goal = np.array([target.x_m, target.y_m, target.heading_rad])
        tabu = self._escape.tabu_circles(t)
        # on a slow reference the robot waits for movers at its point on purpose (_waiting_spot,
        # _heading_across), not for them to clear a way: with guidance waiting too, a robot back at
        # its point sooner met a mover head-on there and was caught (slow_circle_among_movers, check)
        waypoint = self._guidance.waypoint(
            pose[:2], goal, obstacles, tabu, slow_trajectory, may_wait=not slow_trajectory
        )
        if waypoint is not None and self._evasion.active:
            # stepping aside round an obstacle: the way round, backwards if that turns less. Its
            # forward heading turned a robot facing away from the way round through the mover's
            # track, to face the mover, which then chased it (slow_circle_among_movers, check)
            waypoint = replace(waypoint, heading_rad=nearer_way(waypoint.heading_rad, pose[2]))
        waypoint = waypoint or target
        if waypoint is None:
            return ref_states, ref_controls, False
        target = [waypoint.x_m, waypoint.y_m, waypoint.heading_rad]
        return np.tile(target, (base.horizon + 1, 1)), np.zeros((base.horizon, 2)), True

    @staticmethod
    def _meant_velocity(
        pose: np.ndarray,
        speed_mps: float,
        set_point: bool,
        slow_trajectory: bool,
        reference_state: np.ndarray,
        reference_control: np.ndarray,
    ) -> np.ndarray:
        """The velocity [vx, vy] (m/s) mover evasion judges the robot at: where it means to go,
        not where evasion itself takes it. On a set-point, its own speed along its heading; on a
        slow trajectory, 0 (it means to stay: judged against its own flight, a robot reversing
        ahead of a mover saw no closing track and was chased, in the mover's path, metres from
        its reference); on a trajectory, the reference's velocity now (judged at its own speed, a
        robot that started behind its reference saw the crossing mover on course as it drove off
        and off course once evasion had stopped it, every other step, and stayed in the mover's
        path: paper_dynamic_tracking_crossing)."""
        if slow_trajectory:
            return np.zeros(2)
        course, speed = (pose[2], speed_mps) if set_point else (reference_state[2], reference_control[0])
        return float(speed) * np.array([math.cos(course), math.sin(course)])

    def _waiting_spot(
        self, pose: np.ndarray, goal: np.ndarray, obstacles: Sequence[Obstacle]
    ) -> Waypoint | None:
        """Where a robot on its way back to a slow trajectory's point `goal` (x m, y m, heading
        rad) goes instead while a mover is on course to the point: where it would step aside to
        from the point (MoverEvasion), on its own side of the mover's line; None when no mover
        reaches the point before the robot would (at approach_speed_mps) or the robot is at it.
        Driving at the point, it met the mover on its line and was chased metres away by it
        (slow_circle_among_movers, check: rejoins of 13 to 21 s)."""
        g = self.config.guidance
        distance = math.hypot(goal[0] - pose[0], goal[1] - pose[1])
        if distance <= g.point_approach_far_m:
            self._waiting.reset()
            return None
        spot = self._waiting.waypoint(np.asarray(goal, dtype=float), np.zeros(2), obstacles, side_of=pose[:2])
        if spot is not None and self._waiting.soonest_s < distance / g.approach_speed_mps:
            self._waiting.reset()  # the mover passes the point before the robot gets there
            return None
        return spot

    def _heading_across(
        self, pose: np.ndarray, goal: np.ndarray, obstacles: Sequence[Obstacle]
    ) -> float | None:
        """The heading (rad) across the track of a mover on course to a slow trajectory's point
        `goal` within brace_horizon_s, whichever way turns the robot at `pose` less; None when
        none is, or the robot is not at the point (beyond point_approach_far_m)."""
        g = self.config.guidance
        if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) > g.point_approach_far_m:
            self._bracing.reset()
            return None
        step = self._bracing.waypoint(
            np.asarray(goal, dtype=float), np.zeros(2), obstacles, horizon_s=g.brace_horizon_s
        )
        if step is None:
            return None
        return nearer_way(step.heading_rad, pose[2])

    def _escape_waypoint(
        self,
        pose: np.ndarray,
        goal: np.ndarray,
        set_point: bool,
        slow_trajectory: bool,
        evading: bool,
        circles: np.ndarray,
        obstacles: Sequence[Obstacle],
        t: float,
    ) -> Waypoint | None:
        """The deadlock escape's waypoint (escape.py), or None. Not while stepping aside from a
        mover: that robot leaves its way on purpose. On a trajectory, only while the NMPC tracks
        the reference itself (guidance's way round handles a blocked way: escaping from it, a
        robot chased its goal round the far side of a cylinder and fell metres behind,
        paper_dynamic_tracking_crossing), and never on a slow one, where the robot waits for
        movers at its point on purpose (_waiting_spot, _heading_across)."""
        escape = self.config.escape
        if not escape.enabled or slow_trajectory or not (escape.on_trajectories or set_point):
            return None
        if evading or (not set_point and self._guidance.guided):
            self._escape.pause()
            return None

        def plan(xy: np.ndarray, goal_xy: np.ndarray, extra: np.ndarray) -> np.ndarray | None:
            return self._guidance.plan_path(xy, goal_xy, obstacles, extra)

        return self._escape.waypoint(pose, goal, self._pipe.current, circles, plan, t)

    def _tracking_goal(self, reference: Reference, circles: np.ndarray, t: float) -> np.ndarray:
        """The reference a preview ahead, or the first later one outside every inflated obstacle
        (`circles`, inflated_circles)."""
        g = self.config.guidance
        times = t + g.tracking_preview_s + np.arange(0.0, TRACKING_SEARCH_S, self.tau_s)
        states = reference.sample(float(times[0]), self.tau_s, len(times) - 1)[0]
        for state in states:
            if circles.size == 0 or np.all(np.hypot(*(circles[:, :2] - state[:2]).T) > circles[:, 2]):
                return state
        return states[0]

    def _obstacles(self, pose: np.ndarray, obstacles: Sequence[Obstacle]) -> tuple[np.ndarray, np.ndarray]:
        """Centres (slots, N+1, 2) and inflated radii (slots, N+1) (m) at the plan's steps, which
        start the drive's dead time from now."""
        cfg, base = self.config, self.config.nmpc
        centres, radii = predict_obstacles(
            obstacles, pose[:2], cfg.slots, base.tau_s, base.horizon, base.obstacle_prediction
        )
        # a mover at step k is a circle covering its track over [k tau, k tau + mover_sweep_s]:
        # a skid-steer needs time to turn away, so the plan keeps clear of where the mover is
        # about to be, not only of where it is; its margin also grows with predicted travel
        velocity = (centres[:, 1, :] - centres[:, 0, :]) / base.tau_s
        speed = np.hypot(velocity[:, 0], velocity[:, 1])
        half_sweep = 0.5 * cfg.mover_sweep_s
        centres = centres + self._mover_lead_s * velocity[:, None, :]
        travel = speed[:, None] * (self._pipe.delay_s + base.tau_s * np.arange(base.horizon + 1))
        inflated = (
            radii[:, None] + cfg.margin_m + half_sweep * speed[:, None] + cfg.mover_margin_per_m * travel
        )
        return centres, inflated

    def _nearly_stationary(self, reference: Reference, ref_speed_mps: float) -> bool:
        """A set-point, or a trajectory slower than approach_max_reference_speed_mps now: a robot
        must then be brought onto it: it will not come to the robot."""
        return (
            isinstance(reference, SetPoint)
            or ref_speed_mps < self.config.guidance.approach_max_reference_speed_mps
        )

    def _speed_caps(
        self, z0: np.ndarray, goal: np.ndarray, stationary: bool, set_point: bool, evading: bool
    ) -> np.ndarray:
        """|v| cap per predicted step (m/s), reached from the current speed at the drive's
        deceleration: approach_speed_mps within slow_radius_m of the `goal` (m) of a (nearly)
        stationary reference; on the way to a set-point, weak_turn_speed_mps while the robot turns
        less than weak_turn_ratio of what its model predicts (turn_monitor.py); else v_max. No cap
        while `evading` a mover: the approach cap buys docking time for the yaw lag, and a robot
        that can reverse at only the cap is caught by a mover. Not on a trajectory: there the
        monitor slowed an unloaded Husky (paper_dynamic_tracking_crossing, N = 12: rejoined in
        10.3 s, not 5) and a loaded one still collided as often in `check`."""
        cfg, base = self.config, self.config.nmpc
        v_max = max(base.v_max_mps, -base.v_min_mps)
        cap = v_max
        near = math.hypot(z0[0] - goal[0], z0[1] - goal[1]) <= cfg.guidance.slow_radius_m
        if stationary and near and not evading:
            cap = cfg.guidance.approach_speed_mps
        if set_point and self._turns.ratio < cfg.weak_turn_ratio and not evading:
            cap = min(cap, cfg.weak_turn_speed_mps)
        if cap >= v_max:
            return np.full(base.horizon, v_max)
        steps = np.arange(1, base.horizon + 1)
        braking = abs(z0[3]) - cfg.response.max_linear_accel_mps2 * base.tau_s * steps
        return np.minimum(np.maximum(cap, braking), v_max)

    def _warm_guess(self, z0: np.ndarray) -> ExtendedPlan:
        n = self.config.nmpc.horizon
        if self._plan is None:
            return self._rollout(z0, np.zeros((n, 2)))
        plan = self._plan
        states = np.vstack([plan.states[1:], plan.states[-1:]])
        states[:, 2] += 2 * math.pi * round((z0[2] - states[0, 2]) / (2 * math.pi))
        states[0] = z0
        accels = np.vstack([plan.accels[1:], np.zeros((1, 2))])
        return ExtendedPlan(states, accels, np.zeros(n), np.ones(n), np.zeros_like(plan.sigma))

    def _rollout(self, z0: np.ndarray, accels: np.ndarray) -> ExtendedPlan:
        n = accels.shape[0]
        states = [z0]
        for a in accels:
            states.append(np.asarray(self._step(states[-1], a), dtype=float).reshape(-1))
        return ExtendedPlan(
            np.array(states), accels, np.zeros(n), np.ones(n), np.zeros((self.config.slots, n))
        )

    def _accels_for(self, z0: np.ndarray, commands: np.ndarray) -> np.ndarray:
        """Accelerations that move the commanded velocities toward `commands` within the limits."""
        r = self.config.response
        limit = np.array([r.max_linear_accel_mps2, r.max_angular_accel_radps2])
        out, current = [], z0[3:5].copy()
        for command in commands:
            a = np.clip((command - current) / self.tau_s, -limit, limit)
            current = current + a * self.tau_s
            out.append(a)
        return np.array(out)

    # -- solving --------------------------------------------------------------------------
    def _solve(
        self, solver: FatropSolver | IpoptSolver, layout: Layout, p: np.ndarray, guess: ExtendedPlan
    ) -> RawSolution:
        guess_vector = guess.to_vector(layout)
        with deliver_after_solve():  # an interrupt is delivered, never taken for a failed solve
            try:
                raw = solver.solve(p, guess_vector)
            except Exception as exc:  # noqa: BLE001 - a control loop must survive any solver error
                return RawSolution(guess_vector, False, f"exception: {exc}", -1, solver.name)
        if raw.fallback_reason:
            self._solver_fallbacks.append(raw.fallback_reason)
        return raw

    def solve(
        self, state: np.ndarray, reference: Reference, obstacles: Sequence[Obstacle], t: float
    ) -> ControlResult:
        start = time.perf_counter()
        self._solver_fallbacks = []
        cfg, base = self.config, self.config.nmpc
        pose = np.asarray(state, dtype=float).reshape(-1)
        n_real = min(len(obstacles), cfg.slots)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            self._plan = None
            self._pose_filter.reset()
            return self._brake(
                np.full(3, np.nan), n_real, len(obstacles) - n_real, start, "invalid state", False
            )
        turn = self._measured_turn(pose)
        estimate = self._pose_filter.update(pose, self._predicted_speed, self._predicted_turn / base.tau_s)
        if turn is not None:
            self._turns.update(self._predicted_turn, turn)
        z0, omega_now = self._initial_state(pose, turn)
        # the plan starts when the drive acts on its first command: the pose (and obstacles)
        # measured sensing_latency_s ago, predicted over that and the drive's dead time
        t_plan = t + self._plan_start_s
        sampled = reference.sample(t_plan, base.tau_s, base.horizon)
        now = sampled[0][0].copy()  # the reference at t_plan, before guidance replaces it
        stationary = self._nearly_stationary(reference, float(sampled[1][0, 0]))
        ref_states, ref_controls, guided = self._reference(
            pose, estimate, float(z0[3]), reference, sampled, stationary, obstacles, t
        )
        centres, radii = self._obstacles(pose, obstacles)
        reversing = self._approach.reversing or self._escape.reversing
        lookahead = cfg.terminal_lookahead_m * (-1.0 if reversing else 1.0)
        if self._approach.settling and not guided:
            # turning to the goal's heading on the goal (the NMPC tracks the set-point itself, not
            # a waypoint of evasion, escape or guidance): taken ahead, the lateral error pulled the
            # heading towards the line by lateral / lookahead, and the robot rested 6 cm beside
            # the goal 0.11 rad off its heading (trap_cup, N = 5, IPOPT)
            lookahead = 0.0
        caps = self._speed_caps(z0, now, stationary, isinstance(reference, SetPoint), self._evasion.active)
        p = pack_parameters(z0, ref_states, ref_controls, centres, radii, caps, lookahead)
        guess = self._warm_guess(z0)
        hard, soft = self._hard_problem.layout, self._soft_problem.layout

        raw, layout, recovered_by = self._solve(self._hard, hard, p, guess), hard, ""
        if not raw.success:
            first_status = raw.status
            attempts = [("penalty", guess)]
            previous = self._plan.commands[1:] if self._plan is not None else None
            if previous is not None:
                previous = np.vstack([previous, previous[-1:]])
            for name, commands in recovery_commands(
                pose,
                ref_states[-1],
                previous,
                base.horizon,
                base.tau_s,
                (base.v_min_mps, base.v_max_mps),
                cfg.omega_cmd_max_radps,
            ):
                attempts.append((name, self._rollout(z0, self._accels_for(z0, commands))))
            for name, attempt in attempts:
                if name != "penalty":
                    self._soft.reset()
                raw = self._solve(self._soft, soft, p, attempt)
                if raw.success:
                    layout, recovered_by = soft, name
                    break
            if not raw.success:
                self._plan = None
                self._hard.reset()
                return self._brake(pose, n_real, len(obstacles) - n_real, start, first_status, guided)
        plan = ExtendedPlan.from_vector(raw.decision, layout)
        self._plan = plan
        command = plan.states[1, 3:5].copy()
        filtered = False
        if self._filter is not None:
            verdict = self._filter.filter(z0, command, obstacles)
            command, filtered = verdict.command, verdict.intervened
        self._advance(pose, omega_now, command)
        barriers = self._barriers(plan, p, layout, n_real)
        residual = barriers[:, 1:] - plan.decay_slack * (1.0 - base.gamma) * barriers[:, :-1]
        return ControlResult(
            control=command,
            predicted_states=plan.states[:, :3].copy(),
            predicted_controls=plan.commands.copy(),
            clf_slack=plan.clf_slack,
            decay_slack=plan.decay_slack,
            predicted_barrier=barriers,
            safety_active=int(np.sum(residual <= ACTIVE_TOL)),
            status=raw.status,
            success=True,
            fallback="none",
            iterations=raw.iterations,
            solve_time_s=time.perf_counter() - start,
            obstacles_considered=n_real,
            obstacles_ignored=len(obstacles) - n_real,
            recovered_by=recovered_by,
            soft_constraint=bool(np.max(plan.sigma, initial=0.0) > SLACK_TOL),
            guided=guided,
            solver=raw.solver,
            solver_fallback="; ".join(dict.fromkeys(self._solver_fallbacks)),
            plan_start_s=self._plan_start_s,
            escape=self._escape.phase,
            filtered=filtered,
        )

    def _barriers(self, plan: ExtendedPlan, p: np.ndarray, layout: Layout, n_real: int) -> np.ndarray:
        """(obstacles considered, N+1) smallest B over the body discs."""
        problem = self._soft_problem if layout.soft else self._hard_problem
        rows = np.asarray(problem.barriers(plan.to_vector(layout), p), dtype=float)
        per_slot = rows.reshape(self.config.slots, len(self._discs), -1).min(axis=1)
        return per_slot[:n_real]

    def _advance(self, pose: np.ndarray, omega_now: float, command: np.ndarray) -> None:
        """Send `command` down the pipe and predict the control step it starts: the body yaw rate
        at its end, its heading change and its mean speed (what the next step checks)."""
        self._pipe.send(command)
        end_pose, self._omega_body, self._predicted_speed = self._pipe.predict_step(pose, omega_now)
        self._predicted_turn = float(wrap_angle(end_pose[2] - pose[2]))
        self._yaw_prev = float(pose[2])

    def _brake(
        self, pose: np.ndarray, n_real: int, ignored: int, start: float, status: str, guided: bool
    ) -> ControlResult:
        n = self.config.nmpc.horizon
        if np.all(np.isfinite(pose)):
            _, omega_now = self._initial_state(pose, self._measured_turn(pose))
            self._advance(pose, omega_now, np.zeros(2))
        else:
            self._pipe.send(np.zeros(2))
            self._yaw_prev = None
        result = ControlResult.brake(n, n_real, ignored, time.perf_counter() - start, status, guided)
        result.solver_fallback = "; ".join(dict.fromkeys(self._solver_fallbacks))
        result.escape = self._escape.phase
        return result
