"""The husky-cbf OCP, declared once; a hard and a soft (exact-penalty) variant share it.

Decision vector S = [z(0..N) (6 each), a(0..N-1) (2 each), s_v(0..N-1), s_h(0..N-1), sigma]
(sigma only in the soft variant: one slack per obstacle slot and step k = 1..N).
Parameter vector p = [z_fb (6), xi_r(0..N) (3 each), u_r(0..N-1) (2 each),
per slot: centre(0..N) (2 each), inflated radius(0..N); |v| cap(1..N), lookahead].

  min  sum_{m<N} e(m)^T W_xi e(m) + (u(m+1) - u_r(m))^T W_u (.) + a(m)^T W_a a(m)
                 + W1 s_v(m)^2 + W2 (s_h(m) - 1)^2
       + e_N^T P e_N in the reference's frame (along, across at a lookahead point, heading)
       + w_v (v(N) - v_r)^2
       [+ rho sum sigma]                                        (soft variant: exact L1 penalty)
  s.t. z(0) = z_fb;  z(m+1) = F_RK4(z(m), a(m))                (extended model, model.py)
       (1 - alpha) V(m) + s_v(m) - V(m+1) >= 0,  s_v >= 0         (the paper's CLF)
       per slot, disc d and m:  B_d(m+1) - s_h(m) (1 - gamma) B_d(m) [+ sigma] >= 0  (Relax-CBF)
       per slot and disc, at N: |c_d(N) - o(N)|^2 - (r_d + r_o(N) + v(N)^2 / (2 a_max))^2
                                [+ sigma] >= 0                  (can still brake after the horizon)
       v, omega_cmd within the drive's limits, |a| within its acceleration limits, 0 <= s_h <= 1,
       |v(m+1)| <= cap(m)                                (a gentle arrival near a set-point)
       |v -+ half_separation * omega_cmd| <= max wheel speed        (each side's wheels)

u(m+1) = (v, omega_cmd) of z(m+1): the command sent at step m. B_d = |c_d - o|^2 - (r_d + r_o)^2
with c_d the centre of body disc d (footprint.py) and r_o the obstacle's inflated radius (margin,
and for movers a margin growing with their predicted travel).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.backends import NLP, FatropSolver, IpoptSolver, make_solver
from controllers.backends.stagewise import StageIndices
from controllers.husky_cbf.config import HuskyCBFConfig
from controllers.husky_cbf.footprint import disc_cover
from controllers.husky_cbf.model import CONTROL_DIM, STATE_DIM, extended_step
from controllers.model import wrap_angle_sym

INF = float("inf")
#: FATROP iterations for the hard problem, with no IPOPT fallback: past them the problem counts
#: as infeasible and the controller's exact-penalty re-solve follows, which has the hard problem's
#: solution wherever the hard problem is feasible (the penalty is exact) and a plan with the least
#: obstacle slack where it is not. A feasible hard problem converges in far fewer iterations than
#: a line search takes to fail on an infeasible one, and proving infeasibility (IPOPT's
#: restoration phase) costs more still, so the budget bounds a step's solve time; the answer is
#: the hard one wherever the penalty weight (`soft_penalty`) exceeds the obstacle rows'
#: multipliers and the re-solve finds the same local optimum. A lower configured max_iter stays.
HARD_MAX_ITER = 40


@dataclass(frozen=True)
class Layout:
    """Sizes and offsets of S and p."""

    horizon: int
    slots: int
    soft: bool

    @property
    def n_states(self) -> int:
        return STATE_DIM * (self.horizon + 1)

    @property
    def n_controls(self) -> int:
        return CONTROL_DIM * self.horizon

    @property
    def n_sigma(self) -> int:
        return self.slots * self.horizon if self.soft else 0

    @property
    def n_decision(self) -> int:
        return self.n_states + self.n_controls + 2 * self.horizon + self.n_sigma

    @property
    def n_parameters(self) -> int:
        n = self.horizon
        return STATE_DIM + 3 * (n + 1) + 2 * n + self.slots * 3 * (n + 1) + n + 1

    def stages(self) -> StageIndices:
        """Each stage's entries of S: z_k; a_k, s_v(k), s_h(k) and the obstacle slacks of step k."""
        n, i, j = self.horizon, self.n_states, self.n_states + self.n_controls
        states = tuple(tuple(range(STATE_DIM * k, STATE_DIM * (k + 1))) for k in range(n + 1))
        controls = []
        for k in range(n):
            own = [*range(i + CONTROL_DIM * k, i + CONTROL_DIM * (k + 1)), j + k, j + n + k]
            if self.soft:
                own += [j + 2 * n + slot * n + k for slot in range(self.slots)]
            controls.append(tuple(own))
        return StageIndices(states, tuple(controls))


@dataclass
class ExtendedPlan:
    """A solved (or guessed) plan: states (N+1, 6), accelerations (N, 2), slacks."""

    states: np.ndarray
    accels: np.ndarray
    clf_slack: np.ndarray
    decay_slack: np.ndarray
    sigma: np.ndarray  # (slots, N) obstacle slacks (zeros for a hard solve)

    def to_vector(self, layout: Layout) -> np.ndarray:
        parts = [self.states.ravel(), self.accels.ravel(), self.clf_slack, self.decay_slack]
        if layout.soft:
            parts.append(self.sigma.ravel())
        return np.concatenate(parts)

    @classmethod
    def from_vector(cls, w: np.ndarray, layout: Layout) -> ExtendedPlan:
        n, i, j = layout.horizon, layout.n_states, layout.n_states + layout.n_controls
        sigma = w[j + 2 * n :].reshape(layout.slots, n) if layout.soft else np.zeros((layout.slots, n))
        return cls(
            w[:i].reshape(n + 1, STATE_DIM).copy(),
            w[i:j].reshape(n, CONTROL_DIM).copy(),
            w[j : j + n].copy(),
            w[j + n : j + 2 * n].copy(),
            sigma.copy(),
        )

    @property
    def commands(self) -> np.ndarray:
        """(N, 2) commands [v, omega_cmd] sent at steps 0..N-1."""
        return self.states[1:, 3:5]


def pack_parameters(
    z_fb: np.ndarray,
    ref_states: np.ndarray,
    ref_controls: np.ndarray,
    centres: np.ndarray,
    radii: np.ndarray,
    speed_caps: np.ndarray,
    lookahead_m: float,
) -> np.ndarray:
    """p from numeric values: centres (slots, N+1, 2), radii (slots, N+1), |v| caps (N,) (m/s),
    the terminal cost's lookahead (m; negative when the plan should reverse)."""
    per_slot = [np.concatenate([c.ravel(), r]) for c, r in zip(centres, radii, strict=True)]
    return np.concatenate(
        [z_fb, ref_states.ravel(), ref_controls.ravel(), *per_slot, speed_caps, [lookahead_m]]
    )


@dataclass(frozen=True)
class Problem:
    """The NLP of one variant (with its bounds and stages) and a diagnostics function."""

    layout: Layout
    nlp: NLP
    barriers: ca.Function  # (S, p) -> (slots * discs, N+1) B values


@lru_cache(maxsize=32)
def build_problem(config: HuskyCBFConfig, horizon: int, slots: int, soft: bool) -> Problem:
    """Formulate the OCP symbolically (cached per configuration)."""
    cfg, base, resp = config, config.nmpc, config.response
    n = horizon
    layout = Layout(n, slots, soft)
    w = ca.SX.sym("S", layout.n_decision)
    p = ca.SX.sym("p", layout.n_parameters)
    z = ca.reshape(w[: layout.n_states], STATE_DIM, n + 1)
    a = ca.reshape(w[layout.n_states : layout.n_states + layout.n_controls], CONTROL_DIM, n)
    j = layout.n_states + layout.n_controls
    s_v, s_h = w[j : j + n], w[j + n : j + 2 * n]
    sigma = ca.reshape(w[j + 2 * n :], n, slots).T if soft else ca.SX.zeros(slots, n)

    k = 0
    z_fb = p[k : k + STATE_DIM]
    k += STATE_DIM
    ref = ca.reshape(p[k : k + 3 * (n + 1)], 3, n + 1)
    k += 3 * (n + 1)
    u_ref = ca.reshape(p[k : k + 2 * n], 2, n)
    k += 2 * n
    centres, radii = [], []
    for _ in range(slots):
        centres.append(ca.reshape(p[k : k + 2 * (n + 1)], 2, n + 1))
        k += 2 * (n + 1)
        radii.append(p[k : k + n + 1].T)
        k += n + 1
    speed_caps = p[k : k + n]
    lookahead = p[k + n]

    def error(m: int) -> ca.SX:
        return ca.vertcat(z[0, m] - ref[0, m], z[1, m] - ref[1, m], wrap_angle_sym(z[2, m] - ref[2, m]))

    w_xi, w_u, w_v = ca.DM(base.state_weight), ca.DM(base.input_weight), ca.DM(base.clf_weight)
    w_a = ca.DM(np.diag(cfg.accel_weight))
    errors = [error(m) for m in range(n + 1)]
    lyapunov = [ca.bilin(w_v, e, e) for e in errors]
    cost = 0
    for m in range(n):
        du = z[3:5, m + 1] - u_ref[:, m]
        cost += ca.bilin(w_xi, errors[m], errors[m]) + ca.bilin(w_u, du, du) + ca.bilin(w_a, a[:, m], a[:, m])
        cost += base.clf_slack_weight * s_v[m] ** 2 + base.decay_slack_weight * (s_h[m] - 1.0) ** 2
    heading = ref[2, n]
    e_n = errors[n]
    along = ca.cos(heading) * e_n[0] + ca.sin(heading) * e_n[1]
    # across: the lateral error of a point `lookahead` ahead of the robot (behind it when the
    # plan should reverse). Turning toward the reference's line lowers it at once, so a robot
    # beside its line is not held by a short horizon in which turning does not yet pay.
    across = -ca.sin(heading) * e_n[0] + ca.cos(heading) * e_n[1] + lookahead * ca.sin(e_n[2])
    p_along, p_across, p_heading = cfg.terminal_weight
    cost += p_along * along**2 + p_across * across**2 + p_heading * e_n[2] ** 2
    cost += cfg.terminal_speed_weight * (z[3, n] - u_ref[0, n - 1]) ** 2
    if soft:
        cost += cfg.soft_penalty * ca.sum1(ca.vec(sigma))

    step = extended_step(base.tau_s, resp)
    equalities = [z[:, 0] - z_fb] + [z[:, m + 1] - step(z[:, m], a[:, m]) for m in range(n)]
    clf = [(1.0 - base.alpha) * lyapunov[m] + s_v[m] - lyapunov[m + 1] for m in range(n)]

    offsets, r_disc = disc_cover(cfg.footprint, cfg.disc_excess_m)
    safety, barrier_rows = [], []
    for slot in range(slots):
        for d in offsets:
            cx = z[0, :] + d * ca.cos(z[2, :])
            cy = z[1, :] + d * ca.sin(z[2, :])
            dist_sq = (cx - centres[slot][0, :]) ** 2 + (cy - centres[slot][1, :]) ** 2
            r_sum = r_disc + radii[slot]
            b = dist_sq - r_sum**2
            barrier_rows.append(b)
            for m in range(n):
                safety.append(b[m + 1] - s_h[m] * (1.0 - base.gamma) * b[m] + sigma[slot, m])
            braking = z[3, n] ** 2 / (2.0 * resp.max_linear_accel_mps2)
            safety.append(dist_sq[n] - (r_sum[n] + braking) ** 2 + sigma[slot, n - 1])
    caps = [speed_caps[m] - z[3, m + 1] for m in range(n)] + [speed_caps[m] + z[3, m + 1] for m in range(n)]
    wheel, half = cfg.wheel_speed_ratio * resp.max_linear_mps, resp.half_separation_m
    for m in range(1, n + 1):  # both sides' wheel speeds within the limit
        for side in (1.0, -1.0):
            caps += [wheel - (z[3, m] + side * half * z[4, m]), wheel + (z[3, m] + side * half * z[4, m])]
    g = ca.vertcat(*equalities, *clf, *safety, *caps)
    n_eq = STATE_DIM * (n + 1)
    lbg = np.zeros(g.numel())
    ubg = np.concatenate([np.zeros(n_eq), np.full(g.numel() - n_eq, INF)])

    lbz = np.tile([-INF, -INF, -INF, base.v_min_mps, -cfg.omega_cmd_max_radps, -INF], n + 1)
    ubz = np.tile([INF, INF, INF, base.v_max_mps, cfg.omega_cmd_max_radps, INF], n + 1)
    lbz[3:5], ubz[3:5] = -INF, INF  # z(0) is measured: never make it infeasible by a bound
    acc = np.array([resp.max_linear_accel_mps2, resp.max_angular_accel_radps2])
    lbx = np.concatenate([lbz, np.tile(-acc, n), np.zeros(n), np.zeros(n), np.zeros(layout.n_sigma)])
    ubx = np.concatenate([ubz, np.tile(acc, n), np.full(n, INF), np.ones(n), np.full(layout.n_sigma, INF)])
    barriers = ca.Function("barriers", [w, p], [ca.vertcat(*barrier_rows)])
    name = f"husky_cbf_{'soft' if soft else 'hard'}"
    nlp = NLP(name, {"x": w, "p": p, "f": cost, "g": g}, (lbx, ubx, lbg, ubg), layout.stages())
    return Problem(layout, nlp, barriers)


def solver_for(
    config: HuskyCBFConfig, horizon: int, slots: int, soft: bool
) -> tuple[Problem, FatropSolver | IpoptSolver]:
    """The problem and the solver `config.nmpc.solver.backend` names for it; on FATROP, the hard
    problem gets HARD_MAX_ITER iterations and no IPOPT fallback."""
    problem = build_problem(config, horizon, slots, soft)
    options = config.nmpc.solver
    if soft or options.backend != "fatrop":
        return problem, make_solver(problem.nlp, options)
    hard = replace(options, max_iter=min(options.max_iter, HARD_MAX_ITER))
    return problem, make_solver(problem.nlp, hard, fallback_max_iter=0)
