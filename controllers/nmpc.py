"""The NMPC-CLF controller with a BT, CBF or Relax-CBF obstacle constraint (paper Sec. III).

Per step: sample the reference along the horizon, predict the obstacles, warm-start IPOPT from
the previous plan shifted by one step (s_h guess 1), solve, apply the first control.

A problem that controllers.reachability proves to have no solution (a safety row no reachable
position satisfies) is not handed to any solver: it fails at once, with the proof as its status.
When IPOPT fails (infeasible, iteration or time limit, non-finite numbers, exception), the same
NLP is solved again cold from the alternative guesses of controllers.recovery (braking, previous
plan, reversing, straight line), and the first that succeeds is used and counted (`recovered_by`).
On the structured backend these retries are FATROP's alone: its IPOPT fallback answers the step's
own problem, from the warm guess, only.
Fallback when all of them fail: the next control of the last solved plan, if that plan's remaining
states are still collision-free against the obstacles as now predicted; otherwise a braking
command v = 0, omega = 0. The result is marked as a fallback and the loop goes on; `solve` never
raises for a solver failure. A signal (Ctrl-C, SIGTERM) during a solve is not a failure: it
reaches the program's handler (controllers.signals).

A problem posed bit for bit before, this step or the last (a robot standing still in the kinematic
loop), is answered as it was then, not solved again, where the backend's answer depends on the
problem alone (controllers.backends.repeats); a step that ran no solver at all is marked `repeated`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from controllers.backends import FatropSolver, IpoptSolver, RawSolution, make_solver
from controllers.backends.opti import OptiSolver
from controllers.backends.repeats import RepeatedProblems
from controllers.config import NMPCConfig
from controllers.interface import ControlResult, FallbackKind
from controllers.model import step
from controllers.obstacles import Obstacle, predict_obstacles
from controllers.ocp import OCPParameters, Plan, paper_nlp, sx_problem
from controllers.reachability import proven_infeasible
from controllers.recovery import recovery_commands
from controllers.references import Reference
from controllers.signals import deliver_after_solve

#: A safety constraint whose residual is at most this (m or m^2) counts as active.
ACTIVE_TOL = 1e-4
#: The status of a step whose problem controllers.reachability proved to have no solution.
PROVEN_INFEASIBLE = "Proven_Infeasible"


class NMPCController:
    """NMPC with CLF and obstacle constraints; one NLP built per configuration."""

    def __init__(self, config: NMPCConfig) -> None:
        self.config = config
        if config.solver.backend == "opti":
            self._backend: OptiSolver | FatropSolver | IpoptSolver = OptiSolver(config)
        else:
            self._backend = make_solver(paper_nlp(config), config.solver)
        self._problem = sx_problem(config)
        self._layout = self._problem.layout
        self._plan: Plan | None = None  # last successfully solved plan
        self._plan_age = 0  # control steps since that plan was solved
        self._repeats = RepeatedProblems() if self._backend.pure else None
        # the retries from the recovery guesses: FATROP alone on the structured backend. IPOPT from
        # a guess where FATROP failed rarely succeeds, and each try costs a large share of a control
        # period (docs/solvers.md, "Solver retries")
        self._retry_solve = (
            self._backend.solve_without_fallback
            if isinstance(self._backend, FatropSolver)
            else self._backend.solve
        )
        self._solves = [0, 0]  # this step's problems: [solved, answered by self._repeats]
        #: Called with each control step's problem (parameter vector, warm-start guess) before it
        #: is solved (not the retries): how `husky-sim bench` records a closed loop to replay.
        self.on_solve: Callable[[np.ndarray, np.ndarray], None] | None = None

    @property
    def backend_name(self) -> str:
        return self._backend.name

    def reset(self) -> None:
        self._plan, self._plan_age = None, 0
        self._backend.reset()
        if self._repeats is not None:
            self._repeats.clear()

    # -- per-step preparation -------------------------------------------------------------
    def _parameters(
        self, state: np.ndarray, reference: Reference, obstacles: Sequence[Obstacle], t: float
    ) -> OCPParameters:
        cfg = self.config
        ref_states, ref_controls = reference.sample(t, cfg.tau_s, cfg.horizon)
        centres, radii = predict_obstacles(
            obstacles,
            state[:2],
            cfg.obstacle_slots,
            cfg.tau_s,
            cfg.horizon,
            cfg.obstacle_prediction,
        )
        return OCPParameters(state.copy(), ref_states, ref_controls, centres, radii)

    def _initial_guess(self, state: np.ndarray, params: OCPParameters) -> Plan:
        n = self.config.horizon
        if self._plan is None:
            guess = Plan(np.tile(state, (n + 1, 1)), params.ref_controls.copy(), np.zeros(n), np.ones(n))
        else:
            guess = self._plan.shifted(self._plan_age + 1)
            guess.states[:, 2] += 2 * np.pi * np.round((state[2] - guess.states[0, 2]) / (2 * np.pi))
        guess.states[0] = state
        guess.controls[:, 0] = np.clip(guess.controls[:, 0], self.config.v_min_mps, self.config.v_max_mps)
        w = self.config.omega_max_radps
        guess.controls[:, 1] = np.clip(guess.controls[:, 1], -w, w)
        return guess

    # -- fallback ---------------------------------------------------------------------------
    def _previous_plan_is_safe(self, params: OCPParameters, n_real: int) -> bool:
        """Whether the last plan's remaining states keep B >= 0 against the obstacles as now
        predicted (the robot circle model)."""
        if self._plan is None or self._plan_age + 1 >= self.config.horizon:
            return False
        remaining = self._plan.states[self._plan_age + 1 :, :2]
        steps = remaining.shape[0]
        for slot in range(n_real):
            centres = params.obstacle_centres[slot, :steps]
            r_sum = self.config.robot_radius_m + params.obstacle_radii[slot]
            if np.any(np.sum((remaining - centres) ** 2, axis=1) < r_sum**2):
                return False
        return True

    def _fallback(self, state: np.ndarray, params: OCPParameters, n_real: int) -> tuple[Plan, FallbackKind]:
        """The plan to follow after a failed solve: the last plan, one step further on, if it is
        still safe; else a standstill (brake) plan, after which the old plan is dropped."""
        if self._previous_plan_is_safe(params, n_real):
            self._plan_age += 1
            return self._plan.shifted(self._plan_age), "previous-plan"
        self._plan, self._plan_age = None, 0
        n = self.config.horizon
        return Plan(np.tile(state, (n + 1, 1)), np.zeros((n, 2)), np.zeros(n), np.ones(n)), "brake"

    # -- the control step ------------------------------------------------------------------
    def solve(
        self, state: np.ndarray, reference: Reference, obstacles: Sequence[Obstacle], t: float
    ) -> ControlResult:
        start = time.perf_counter()
        if self._repeats is not None:
            self._repeats.next_step()
        self._solves = [0, 0]
        state = np.asarray(state, dtype=float).reshape(-1)
        n_real = min(len(obstacles), self.config.obstacle_slots)
        ignored = len(obstacles) - n_real
        if state.shape != (3,) or not np.all(np.isfinite(state)):
            self._plan, self._plan_age = None, 0
            return self._result_without_plan(state, n_real, ignored, start, "invalid state")
        params = self._parameters(state, reference, obstacles, t)
        guess = self._initial_guess(state, params)
        p_vec, guess_vector = params.to_vector(), guess.to_vector(self._layout)
        if self.on_solve is not None:
            self.on_solve(p_vec, guess_vector)
        proof = proven_infeasible(self.config, params)
        if proof:  # no solver, from no guess, can succeed: none is asked
            self._backend.reset()  # as after a failed solve: the next solve starts cold
            raw = RawSolution(guess_vector, False, f"{PROVEN_INFEASIBLE} ({proof})", -1)
        else:
            with deliver_after_solve():  # an interrupt is delivered, never taken for a failed solve
                try:
                    raw = self._run_solver(p_vec, guess_vector)
                except Exception as exc:  # noqa: BLE001 - a control loop must survive any solver error
                    raw = RawSolution(guess_vector, False, f"exception: {exc}", -1, self.backend_name)
        recovered_by = ""
        solver_fallbacks = [raw.fallback_reason]  # the first solve's, kept when a retry answers
        if not raw.success and not proof:
            retry, recovered_by = self._retry(state, params, p_vec, guess_vector)
            raw = retry or raw
            solver_fallbacks.append(raw.fallback_reason)
        if raw.success:
            plan, fallback = Plan.from_vector(raw.decision, self._layout), "none"
            self._plan, self._plan_age = plan, 0
        else:
            plan, fallback = self._fallback(state, params, n_real)
        safety, barriers, _ = self._problem.diagnostics(plan.to_vector(self._layout), p_vec)
        safety = np.asarray(safety, dtype=float).reshape(-1)
        barriers = np.asarray(barriers, dtype=float).reshape(
            self.config.obstacle_slots, self.config.horizon + 1
        )
        per_slot = safety.size // self.config.obstacle_slots if self.config.obstacle_slots else 0
        active = int(np.sum(safety[: n_real * per_slot] <= ACTIVE_TOL)) if raw.success else 0
        return ControlResult(
            control=plan.controls[0].copy(),
            predicted_states=plan.states,
            predicted_controls=plan.controls,
            clf_slack=plan.clf_slack,
            decay_slack=plan.decay_slack,
            predicted_barrier=barriers[:n_real],
            safety_active=active,
            status=raw.status,
            success=raw.success,
            fallback=fallback,
            iterations=raw.iterations,
            solve_time_s=time.perf_counter() - start,
            obstacles_considered=n_real,
            obstacles_ignored=ignored,
            recovered_by=recovered_by,
            solver=raw.solver,
            solver_fallback="; ".join(r for r in dict.fromkeys(solver_fallbacks) if r),
            repeated=self._solves[0] == 0 and self._solves[1] > 0,
        )

    def _run_solver(self, p_vec: np.ndarray, guess: np.ndarray, retry: bool = False) -> RawSolution:
        """The backend's answer to one problem (`retry`: the retries' solver), looked up where this
        step or the one before posed the same problem (controllers.backends.repeats)."""
        solve = self._retry_solve if retry else self._backend.solve
        if self._repeats is None:
            raw, repeated = solve(p_vec, guess), False
        else:
            raw, repeated = self._repeats.solve(solve, p_vec, guess, b"retry" if retry else b"")
        self._solves[1 if repeated else 0] += 1
        return raw

    def _retry(
        self, state: np.ndarray, params: OCPParameters, p_vec: np.ndarray, tried: np.ndarray
    ) -> tuple[RawSolution | None, str]:
        """Cold re-solves from the recovery guesses; the first success and its guess's name.
        `tried`: the guess the step's own solve failed from."""
        cfg = self.config
        previous = self._plan.shifted(self._plan_age + 1).controls if self._plan is not None else None
        candidates = recovery_commands(
            state,
            params.ref_states[-1],
            previous,
            cfg.horizon,
            cfg.tau_s,
            (cfg.v_min_mps, cfg.v_max_mps),
            cfg.omega_max_radps,
        )
        for name, commands in candidates:
            states = [state]
            for command in commands:
                states.append(step(states[-1], command, cfg.tau_s))
            n = cfg.horizon
            guess = Plan(np.array(states), commands.copy(), np.zeros(n), np.ones(n)).to_vector(self._layout)
            if self._backend.pure and np.array_equal(guess, tried):
                continue  # a pure backend, its fallback included, has just failed from this guess
            self._backend.reset()
            with deliver_after_solve():
                try:
                    raw = self._run_solver(p_vec, guess, retry=True)
                except Exception:  # noqa: BLE001 - try the next guess
                    continue
            if raw.success:
                return raw, name
        return None, ""

    def _result_without_plan(
        self, state: np.ndarray, n_real: int, ignored: int, start: float, status: str
    ) -> ControlResult:
        return ControlResult.brake(self.config.horizon, n_real, ignored, time.perf_counter() - start, status)
