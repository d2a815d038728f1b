"""husky-cbf: the paper's Relax-CBF NMPC-CLF extended with what a Husky's physics needs.

Per control step:
1. estimate the state: the initial state of the extended model at the instant the drive will act
   on this step's command (delay.py: after the drive's dead time), the pose and body yaw rate
   predicted over the sensing latency and the dead time from the measured pose and the estimated
   yaw rate, under the commands already sent; the filtered pose (localisation.py); and the
   obstacles: those measured now and those remembered out of the sensor's view (obstacle_memory.py);
2. build the Situation (behaviours/base.py): the reference's kind, the goal, the obstacles;
3. the arbiter (arbiter.py) chooses the target: the reference itself, or a behaviour's or the
   planner's waypoint (recovery, yielding to movers, approach, detour);
4. the NMPC's reference and obstacles (_tracked): the reference sampled along the horizon, or
   shifted by a step aside from its point, or the target held over the horizon; and the nearest
   obstacles predicted by the mover model (movers.py);
5. solve: the hard OCP (ocp.py); if it fails, the same OCP with an exactly penalised obstacle
   slack (a feasible hard plan is its optimum, so this also recovers solves that failed from a
   poor start); if that fails too, again from each of controllers.recovery's guesses; else brake.
   After a step whose plan needed the slack, the penalised OCP goes first: the hard one most
   likely has no solution again, and proving that costs as much as a solve. Its plan is taken if
   it needs the slack again (the hard OCP then has no solution: a feasible one would be the
   penalised optimum); else the hard OCP is solved as usual, its plan preferred;
6. the safety filter (safety_filter.py), when configured, on the command;
7. the result: whether the step was guided, penalised (obstacle slack > 0) or recovered, and the
   recovery phase.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from controllers.backends import FatropSolver, IpoptSolver, RawSolution
from controllers.husky_cbf.arbiter import Arbiter, Decision, Mode
from controllers.husky_cbf.behaviours.base import ReferenceKind, Situation
from controllers.husky_cbf.behaviours.yield_to_movers import RobotLimits
from controllers.husky_cbf.config import HuskyCBFConfig
from controllers.husky_cbf.delay import CommandPipe
from controllers.husky_cbf.footprint import disc_cover
from controllers.husky_cbf.localisation import PoseFilter
from controllers.husky_cbf.model import extended_step
from controllers.husky_cbf.movers import MoverModel, is_static
from controllers.husky_cbf.obstacle_memory import ObstacleMemory
from controllers.husky_cbf.ocp import ExtendedPlan, Layout, pack_parameters, solver_for
from controllers.husky_cbf.safety_filter import SafetyFilter
from controllers.husky_cbf.turn_monitor import TurnMonitor
from controllers.interface import ControlResult
from controllers.model import wrap_angle
from controllers.obstacles import Obstacle
from controllers.recovery import recovery_commands
from controllers.references import Reference, SetPoint
from controllers.signals import deliver_after_solve

#: An obstacle constraint residual (m^2) at most this counts as active.
ACTIVE_TOL = 1e-4
#: An obstacle slack (m^2) above this means the plan needed the penalised slack.
SLACK_TOL = 1e-6
#: Weight of the measured heading change in the body yaw-rate estimate (0: model only).
YAW_RATE_CORRECTION = 0.5
#: Tracking: the goal is the reference this far (s) ahead, so that it leads the robot on ...
TRACKING_PREVIEW_S = 1.0
#: ... or the first later point outside every inflated obstacle, searched this far (s) past it
#: (a mover covering the reference now is soon gone) ...
TRACKING_SEARCH_S = 5.0
#: ... past the first point clear of the static obstacles, searched this far (s): at the slowest
#: trajectory (behaviours.base.SLOW_REFERENCE_MPS) that passes 3 m, wider than an inflated
#: obstacle, so the goal lies beyond what stands on the reference, never inside it
STATIC_SEARCH_S = 30.0
#: Turn monitor (turn_monitor.py): over this window (s), once the model predicted at least
#: WEAK_TURN_MIN_RAD of heading change, ...
WEAK_TURN_WINDOW_S = 1.6
WEAK_TURN_MIN_RAD = 0.3
#: ... a robot on its way to a set-point that turned less than this fraction of it ...
WEAK_TURN_RATIO = 0.4
#: ... is held to this speed (m/s): it may not steer round what its plan goes round, and must be
#: able to stop before it
WEAK_TURN_SPEED_MPS = 0.4


class HuskyCBFController:
    """The `husky-cbf` controller; implements controllers.interface.Controller."""

    def __init__(self, config: HuskyCBFConfig) -> None:
        self.config = config
        base = config.nmpc
        self._hard_problem, self._hard = solver_for(config, base.horizon, config.slots, soft=False)
        self._soft_problem, self._soft = solver_for(config, base.horizon, config.slots, soft=True)
        self._solver_fallbacks: list[str] = []  # this step's reasons the structured solver failed
        self._discs, self._disc_radius = disc_cover(config.footprint, config.disc_excess_m)
        self._pipe = CommandPipe(config.response, base.tau_s, config.measurement_delay_s)
        # the planner and yielding see a mover as wide as the NMPC does at the horizon's middle
        plan_s = config.measurement_delay_s + 0.5 * base.horizon * base.tau_s
        inflation_m = self._disc_radius + config.margin_m
        self.movers = MoverModel.for_plan(config.movers, inflation_m, self._pipe.delay_s, plan_s)
        footprint = config.footprint
        swing_m = math.hypot(footprint.half_length_m, footprint.half_width_m) - self._disc_radius
        self.arbiter = Arbiter.build(config, self.movers, base.tau_s, swing_m)
        self._step = extended_step(base.tau_s, config.response)
        #: from now to the instant the first command acts (s): the prediction's span less the latency
        self._plan_start_s = max(self._pipe.delay_s - config.sensing_latency_s, 0.0)
        self._pose_filter = PoseFilter(config.pose_noise, base.tau_s)
        self._memory = ObstacleMemory(config.sensor_fov_deg)
        self._turns = TurnMonitor(round(WEAK_TURN_WINDOW_S / base.tau_s), WEAK_TURN_MIN_RAD)
        self._filter = (
            SafetyFilter(
                config.response,
                base.tau_s,
                self._discs,
                self._disc_radius,
                config.movers.accel_bound_mps2,
                config.measurement_delay_s,
                config.yielding.horizon_s,
                config.omega_cmd_max_radps,
                RobotLimits.of(config).leave_s(2.0 * self._disc_radius),
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
        self._needed_slack = False  # whether the last plan needed the penalised obstacle slack
        self._pipe.reset()
        self._omega_body = 0.0  # body yaw rate predicted for now (rad/s)
        self._predicted_turn = 0.0  # heading change predicted over the last control step (rad)
        self._predicted_speed = 0.0  # mean body speed predicted over the last control step (m/s)
        self._yaw_prev: float | None = None
        self.arbiter.reset()
        self._pose_filter.reset()
        self._memory.reset()
        self._turns.reset()
        self._hard.reset()
        self._soft.reset()
        if self._filter is not None:
            self._filter.reset()

    # -- 1. state estimate ----------------------------------------------------------------
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

    # -- 2. the situation -----------------------------------------------------------------
    def _situation(
        self,
        pose: np.ndarray,
        estimate: np.ndarray,
        speed_mps: float,
        reference: Reference,
        sampled: tuple[np.ndarray, np.ndarray],
        obstacles: Sequence[Obstacle],
        t: float,
    ) -> Situation:
        """What the behaviours judge this step; `sampled` is the reference sampled along the
        horizon (its yaw-rate feed-forward already in commanded units)."""
        ref_states, ref_controls = sampled
        set_point = isinstance(reference, SetPoint)
        kind = ReferenceKind.of(set_point, float(ref_controls[0, 0]))
        circles = self.movers.body_circles(obstacles, pose[:2])
        static = np.array([is_static(o) for o in obstacles], dtype=bool)
        goal = ref_states[-1] if set_point else self._tracking_goal(reference, circles, static, t)
        return Situation(
            pose=pose,
            estimate=estimate,
            speed_mps=speed_mps,
            kind=kind,
            goal=goal,
            reference_state=ref_states[0],
            reference_speed_mps=float(ref_controls[0][0]),
            obstacles=obstacles,
            circles=circles,
            command=self._pipe.current,
            t=t,
        )

    def _tracking_goal(
        self, reference: Reference, circles: np.ndarray, static: np.ndarray, t: float
    ) -> np.ndarray:
        """The reference TRACKING_PREVIEW_S ahead, or the first later one outside every inflated
        obstacle (`circles`, MoverModel.body_circles; `static`: which of them are static): searched
        TRACKING_SEARCH_S from the first point clear of the static ones (STATIC_SEARCH_S at most)."""
        steps = round(STATIC_SEARCH_S / self.tau_s)
        states = reference.sample(t + TRACKING_PREVIEW_S, self.tau_s, steps)[0]
        if circles.size == 0:
            return states[0]
        gaps = np.hypot(states[:, None, 0] - circles[:, 0], states[:, None, 1] - circles[:, 1])
        outside = gaps > circles[:, 2]
        clear_of_static = np.all(outside[:, static], axis=1)
        first = int(np.argmax(clear_of_static)) if clear_of_static.any() else 0
        window = np.all(outside[first : first + round(TRACKING_SEARCH_S / self.tau_s)], axis=1)
        return states[first + int(np.argmax(window))] if window.any() else states[first]

    # -- 4. the NMPC's reference and limits -------------------------------------------------
    def _feed_forward(self, sampled: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The sampled reference with its yaw-rate feed-forward turned into a commanded yaw rate
        (through the drive's yaw gain, within its limit), in place."""
        cfg = self.config
        ref_states, ref_controls = sampled
        w = cfg.omega_cmd_max_radps
        ref_controls[:, 1] = np.clip(ref_controls[:, 1] / cfg.response.yaw_gain, -w, w)
        return ref_states, ref_controls

    def _tracked(
        self, decision: Decision, sampled: tuple[np.ndarray, np.ndarray], kind: ReferenceKind
    ) -> tuple[np.ndarray, np.ndarray]:
        """The states and feed-forward (N+1, 3), (N, 2) the OCP tracks: the reference itself; a
        step aside from a trajectory's point, as the reference shifted by that step (the target
        moves on with the reference, and the robot keeps its pace beside it); else the decision's
        target held over the horizon at rest."""
        n = self.config.nmpc.horizon
        if decision.target is None:
            return sampled
        target = decision.target
        if decision.mode is Mode.YIELD and kind is ReferenceKind.TRAJECTORY:
            states, controls = sampled
            shifted = states.copy()
            shifted[:, :2] += np.array([target.x_m, target.y_m]) - states[0, :2]
            return shifted, controls
        return np.tile([target.x_m, target.y_m, target.heading_rad], (n + 1, 1)), np.zeros((n, 2))

    def _speed_caps(
        self, z0: np.ndarray, goal: np.ndarray, stationary: bool, set_point: bool, evading: bool
    ) -> np.ndarray:
        """|v| cap per predicted step (m/s), reached from the current speed at the drive's
        deceleration: approach.speed_mps within approach.slow_radius_m of the `goal` (m) of a
        (nearly) stationary reference; on the way to a set-point, WEAK_TURN_SPEED_MPS while the
        robot turns less than WEAK_TURN_RATIO of what its model predicts (turn_monitor.py); else
        v_max. No cap while `evading` a mover (stepping aside): a robot that could reverse at
        only the cap would be caught. The turn monitor caps set-points only: on a trajectory the
        robot must keep up with its reference."""
        cfg, base = self.config, self.config.nmpc
        v_max = max(base.v_max_mps, -base.v_min_mps)
        cap = v_max
        near = math.hypot(z0[0] - goal[0], z0[1] - goal[1]) <= cfg.approach.slow_radius_m
        if stationary and near and not evading:
            cap = cfg.approach.speed_mps
        if set_point and self._turns.ratio < WEAK_TURN_RATIO and not evading:
            cap = min(cap, WEAK_TURN_SPEED_MPS)
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

    def _slack(self, raw: RawSolution) -> float:
        """The largest obstacle slack (m^2) of a solution of the penalised OCP."""
        plan = ExtendedPlan.from_vector(raw.decision, self._soft_problem.layout)
        return float(np.max(plan.sigma, initial=0.0))

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
            return self._brake(np.full(3, np.nan), n_real, len(obstacles) - n_real, start, "invalid state")
        # 1. the state where the drive acts on this step's command, the filtered pose, and the
        # obstacles measured now with those remembered out of the sensor's view
        obstacles, ages = self._memory.update(pose, obstacles, t)
        n_real = min(len(obstacles), cfg.slots)
        turn = self._measured_turn(pose)
        estimate = self._pose_filter.update(pose, self._predicted_speed, self._predicted_turn / base.tau_s)
        if turn is not None:
            self._turns.update(self._predicted_turn, turn)
        z0, omega_now = self._initial_state(pose, turn)
        # the plan starts when the drive acts on its first command: the pose (and obstacles)
        # measured sensing_latency_s ago, predicted over that and the drive's dead time
        t_plan = t + self._plan_start_s
        sampled = self._feed_forward(reference.sample(t_plan, base.tau_s, base.horizon))
        now = sampled[0][0].copy()  # the reference at t_plan, before a target replaces it
        # 2. the situation; 3. the arbiter's decision
        situation = self._situation(pose, estimate, float(z0[3]), reference, sampled, obstacles, t)
        decision = self.arbiter.decide(situation)
        guided = decision.guided
        # 4. what the NMPC tracks, its obstacles and limits
        ref_states, ref_controls = self._tracked(decision, sampled, situation.kind)
        centres, radii = self.movers.nmpc_obstacles(
            pose[:2], obstacles, cfg.slots, base.tau_s, base.horizon, base.obstacle_prediction, cfg.margin_m
        )
        lookahead = cfg.terminal_lookahead_m * (-1.0 if decision.reversing else 1.0)
        if decision.settling and not guided:
            # turning to the goal's heading on the goal (the NMPC tracks the set-point itself):
            # a lateral error taken ahead of the robot would pull its heading towards the line
            lookahead = 0.0
        kind = situation.kind
        stationary, set_point = kind is not ReferenceKind.TRAJECTORY, kind is ReferenceKind.SET_POINT
        caps = self._speed_caps(z0, now, stationary, set_point, decision.stepping_aside)
        p = pack_parameters(z0, ref_states, ref_controls, centres, radii, caps, lookahead)
        guess = self._warm_guess(z0)
        hard, soft = self._hard_problem.layout, self._soft_problem.layout

        # 5. solve: hard, then soft from the warm guess and from each recovery guess, else brake
        # (soft first while the last plan needed its slack: a plan that needs it again is taken)
        penalised = self._solve(self._soft, soft, p, guess) if self._needed_slack else None
        if penalised is not None and penalised.success and self._slack(penalised) > SLACK_TOL:
            raw, layout, recovered_by = penalised, soft, "penalty"
        else:
            raw, layout, recovered_by = self._solve(self._hard, hard, p, guess), hard, ""
        if not raw.success and penalised is not None and penalised.success:
            raw, layout, recovered_by = penalised, soft, "penalty"
        if not raw.success:
            first_status = raw.status
            attempts = [] if penalised is not None else [("penalty", guess)]
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
                return self._brake(pose, n_real, len(obstacles) - n_real, start, first_status, decision)
        plan = ExtendedPlan.from_vector(raw.decision, layout)
        self._plan = plan
        self._needed_slack = bool(np.max(plan.sigma, initial=0.0) > SLACK_TOL)  # zeros in a hard plan
        command = plan.states[1, 3:5].copy()
        # 6. the safety filter
        filtered = False
        if self._filter is not None:
            verdict = self._filter.filter(z0, plan.states[1:, 3:5], obstacles, ages)
            command, filtered = verdict.command, verdict.intervened
        # 7. the result
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
            soft_constraint=self._needed_slack,
            guided=guided,
            solver=raw.solver,
            solver_fallback="; ".join(dict.fromkeys(self._solver_fallbacks)),
            plan_start_s=self._plan_start_s,
            escape=self.arbiter.recovery.phase,
            filtered=filtered,
            mode=decision.mode.value,
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
        self,
        pose: np.ndarray,
        n_real: int,
        ignored: int,
        start: float,
        status: str,
        decision: Decision | None = None,
    ) -> ControlResult:
        n = self.config.nmpc.horizon
        if self._filter is not None:
            self._filter.reset()  # braking was sent unchecked: it is the trajectory now held
        if np.all(np.isfinite(pose)):
            _, omega_now = self._initial_state(pose, self._measured_turn(pose))
            self._advance(pose, omega_now, np.zeros(2))
        else:
            self._pipe.send(np.zeros(2))
            self._yaw_prev = None
        guided, mode = (False, "") if decision is None else (decision.guided, decision.mode.value)
        result = ControlResult.brake(n, n_real, ignored, time.perf_counter() - start, status, guided, mode)
        result.solver_fallback = "; ".join(dict.fromkeys(self._solver_fallbacks))
        result.escape = self.arbiter.recovery.phase
        return result
