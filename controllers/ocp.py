"""The paper's OCP (Sec. III-C) declared once, readable, for any CasADi backend.

Decision vector S = [xi(0..N), u(0..N-1), s_v(0..N-1), s_h(0..N-1)] (s_h only for Relax-CBF;
BT and CBF fix s_h = 1, so it is not a variable there). Parameter vector
p = [xi_fb, xi_r(0..N), u_r(0..N-1), per obstacle slot: centre(0..N), radius].

  min  sum_{m=0}^{N-1} e(m)^T W_xi e(m) + (u(m)-u_r(m))^T W_u (u(m)-u_r(m))
                       + W1 s_v(m)^2 + W2 (s_h(m) - 1)^2
  s.t. xi(0) = xi_fb                                       (initial state)
       xi(m+1) = F_RK4(xi(m), u(m))                         (multiple shooting)
       (1 - alpha) V(m) + s_v(m) - V(m+1) >= 0,  s_v >= 0   (CLF, V = e^T W_v e)
       safety(obstacle, m) >= 0                             (none | bt | cbf | relax-cbf)
       v_min <= v <= v_max, |omega| <= omega_max,  0 <= s_h <= 1

e(m) = xi(m) - xi_r(m) with its heading component wrapped to (-pi, pi] by atan2(sin, cos), in
the cost and in V alike. As in the paper, the stage sum runs over m = 0..N-1 (no terminal cost):
xi(N) enters only through the CLF constraint. s_v >= 0 is ours (a negative CLF slack would only
tighten the constraint and is never optimal). The bounds 0 <= s_h <= 1 are ours too; see
controllers.constraints for why both are needed.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.backends.nlp import NLP, RedundantBounds
from controllers.backends.stagewise import StageIndices
from controllers.config import NMPCConfig
from controllers.constraints import SAFETY_BUILDERS, barrier
from controllers.model import CONTROL_DIM, STATE_DIM, rk4_step, wrap_angle_sym

INF = float("inf")


@dataclass(frozen=True)
class OCPLayout:
    """Sizes and offsets of the decision and parameter vectors for one configuration."""

    horizon: int
    slots: int
    has_decay_slack: bool

    @property
    def n_decision(self) -> int:
        n = self.horizon
        return STATE_DIM * (n + 1) + CONTROL_DIM * n + n + (n if self.has_decay_slack else 0)

    @property
    def n_parameters(self) -> int:
        n = self.horizon
        return STATE_DIM * (n + 2) + CONTROL_DIM * n + self.slots * (2 * (n + 1) + 1)

    def stages(self) -> StageIndices:
        """Each stage's entries of S: x_k; u_k with s_v(k) (and s_h(k)) as stage k's controls."""
        n = self.horizon
        i = STATE_DIM * (n + 1)
        j = i + CONTROL_DIM * n
        states = tuple(tuple(range(STATE_DIM * k, STATE_DIM * (k + 1))) for k in range(n + 1))
        controls = []
        for k in range(n):
            own = [*range(i + CONTROL_DIM * k, i + CONTROL_DIM * (k + 1)), j + k]
            controls.append(tuple(own + ([j + n + k] if self.has_decay_slack else [])))
        return StageIndices(states, tuple(controls))


@dataclass
class Plan:
    """A solved (or guessed) trajectory: states (N+1, 3), controls (N, 2), slacks (N,)."""

    states: np.ndarray
    controls: np.ndarray
    clf_slack: np.ndarray
    decay_slack: np.ndarray

    def to_vector(self, layout: OCPLayout) -> np.ndarray:
        parts = [self.states.ravel(), self.controls.ravel(), self.clf_slack]
        if layout.has_decay_slack:
            parts.append(self.decay_slack)
        return np.concatenate(parts)

    @classmethod
    def from_vector(cls, vector: np.ndarray, layout: OCPLayout) -> Plan:
        n = layout.horizon
        w = np.asarray(vector, dtype=float).reshape(-1)
        i = STATE_DIM * (n + 1)
        j = i + CONTROL_DIM * n
        states = w[:i].reshape(n + 1, STATE_DIM)
        controls = w[i:j].reshape(n, CONTROL_DIM)
        clf_slack = w[j : j + n]
        decay_slack = w[j + n : j + 2 * n] if layout.has_decay_slack else np.ones(n)
        return cls(states.copy(), controls.copy(), clf_slack.copy(), decay_slack.copy())

    def shifted(self, steps: int) -> Plan:
        """Drop the first `steps` steps and repeat the last state/control (warm start)."""
        n = self.controls.shape[0]
        idx_x = np.minimum(np.arange(n + 1) + steps, n)
        idx_u = np.minimum(np.arange(n) + steps, n - 1)
        keep = np.arange(n) + steps < n
        return Plan(
            self.states[idx_x].copy(),
            self.controls[idx_u].copy(),
            np.where(keep, self.clf_slack[idx_u], 0.0),
            np.where(keep, self.decay_slack[idx_u], 1.0),
        )


@dataclass(frozen=True)
class OCPParameters:
    """Numeric values of everything the OCP is parameterised by at one control step."""

    feedback: np.ndarray  # measured state (3,)
    ref_states: np.ndarray  # (N+1, 3), headings already unwrapped next to the measured heading
    ref_controls: np.ndarray  # (N, 2)
    obstacle_centres: np.ndarray  # (slots, N+1, 2)
    obstacle_radii: np.ndarray  # (slots,)

    def to_vector(self) -> np.ndarray:
        slots, points = len(self.obstacle_radii), len(self.ref_states)
        centres = np.reshape(self.obstacle_centres, (slots, points, 2)).transpose(0, 2, 1)
        per_slot = np.hstack(  # each slot: its x's, its y's, its radius
            [centres.reshape(slots, 2 * points), np.reshape(self.obstacle_radii, (slots, 1))]
        )
        return np.concatenate(
            [self.feedback, self.ref_states.ravel(), self.ref_controls.ravel(), per_slot.ravel()]
        )


@dataclass
class OCPSymbols:
    """Symbolic decision variables and parameters, shaped for reading the OCP."""

    states: ca.SX | ca.MX  # (3, N+1)
    controls: ca.SX | ca.MX  # (2, N)
    clf_slack: ca.SX | ca.MX  # (N, 1)
    decay_slack: ca.SX | ca.MX  # (N, 1), constant ones unless Relax-CBF
    parameters: ca.SX | ca.MX  # (n_parameters, 1)


@dataclass
class OCPExpressions:
    """Cost and constraint groups of the OCP; each group is expr with lower/upper bounds."""

    cost: ca.SX | ca.MX
    equalities: ca.SX | ca.MX  # == 0
    clf: ca.SX | ca.MX  # >= 0
    safety: ca.SX | ca.MX  # >= 0, ordered slot-major (slot 0 steps, slot 1 steps, ...)
    barriers: ca.SX | ca.MX  # (slots, N+1) B values of the predicted states (diagnostics)


def split_parameters(p: ca.SX | ca.MX, layout: OCPLayout) -> dict[str, object]:
    """Symbolic views of the parameter vector (the inverse of OCPParameters.to_vector)."""
    n = layout.horizon
    i = 0
    feedback = p[i : i + STATE_DIM]
    i += STATE_DIM
    ref_states = ca.reshape(p[i : i + STATE_DIM * (n + 1)], STATE_DIM, n + 1)
    i += STATE_DIM * (n + 1)
    ref_controls = ca.reshape(p[i : i + CONTROL_DIM * n], CONTROL_DIM, n)
    i += CONTROL_DIM * n
    centres, radii = [], []
    for _ in range(layout.slots):
        centres.append(ca.reshape(p[i : i + 2 * (n + 1)], n + 1, 2).T)
        i += 2 * (n + 1)
        radii.append(p[i])
        i += 1
    return dict(
        feedback=feedback,
        ref_states=ref_states,
        ref_controls=ref_controls,
        centres=centres,
        radii=radii,
    )


def _state_error(state: ca.SX | ca.MX, ref: ca.SX | ca.MX) -> ca.SX | ca.MX:
    """xi - xi_r with the heading error wrapped to (-pi, pi]."""
    return ca.vertcat(state[0] - ref[0], state[1] - ref[1], wrap_angle_sym(state[2] - ref[2]))


def formulate(config: NMPCConfig, sym: OCPSymbols, layout: OCPLayout) -> OCPExpressions:
    """Build the OCP's cost and constraints from symbols (works for SX and MX)."""
    n = config.horizon
    w_xi = ca.DM(config.state_weight)
    w_u = ca.DM(config.input_weight)
    w_v = ca.DM(config.clf_weight)
    par = split_parameters(sym.parameters, layout)
    x, u = sym.states, sym.controls

    errors = [_state_error(x[:, m], par["ref_states"][:, m]) for m in range(n + 1)]
    lyapunov = [ca.bilin(w_v, e, e) for e in errors]

    cost = 0
    for m in range(n):
        du = u[:, m] - par["ref_controls"][:, m]
        cost += ca.bilin(w_xi, errors[m], errors[m]) + ca.bilin(w_u, du, du)
        cost += config.clf_slack_weight * sym.clf_slack[m] ** 2
        if layout.has_decay_slack:
            cost += config.decay_slack_weight * (sym.decay_slack[m] - 1.0) ** 2

    equalities = [x[:, 0] - par["feedback"]]
    equalities += [x[:, m + 1] - rk4_step(x[:, m], u[:, m], config.tau_s) for m in range(n)]
    clf = [(1.0 - config.alpha) * lyapunov[m] + sym.clf_slack[m] - lyapunov[m + 1] for m in range(n)]

    builder = SAFETY_BUILDERS[config.safety]
    position = x[:2, :]
    safety, barriers = [], []
    for centre, radius in zip(par["centres"], par["radii"], strict=True):
        r_sum = config.robot_radius_m + radius
        barriers.append(barrier(position, centre, r_sum))
        if builder is not None:
            safety.append(builder(position, centre, r_sum, config.gamma, sym.decay_slack).T)
    return OCPExpressions(
        cost=cost,
        equalities=ca.vertcat(*equalities),
        clf=ca.vertcat(*clf),
        safety=ca.vertcat(*safety) if safety else ca.DM.zeros(0, 1),
        barriers=ca.vertcat(*barriers) if barriers else ca.DM.zeros(0, n + 1),
    )


def decision_bounds(config: NMPCConfig, layout: OCPLayout) -> tuple[np.ndarray, np.ndarray]:
    """Simple bounds on S: states free, input box, s_v >= 0, 0 <= s_h <= 1."""
    n = layout.horizon
    lb = Plan(
        np.full((n + 1, STATE_DIM), -INF),
        np.tile([config.v_min_mps, -config.omega_max_radps], (n, 1)),
        np.zeros(n),
        np.zeros(n),
    )
    ub = Plan(
        np.full((n + 1, STATE_DIM), INF),
        np.tile([config.v_max_mps, config.omega_max_radps], (n, 1)),
        np.full(n, INF),
        np.ones(n),
    )
    return lb.to_vector(layout), ub.to_vector(layout)


def layout_for(config: NMPCConfig) -> OCPLayout:
    return OCPLayout(config.horizon, config.obstacle_slots, config.uses_decay_slack)


@dataclass(frozen=True)
class SXProblem:
    """The OCP in CasADi SX: decision and parameter symbols with their expressions."""

    layout: OCPLayout
    decision: ca.SX
    parameters: ca.SX
    expressions: OCPExpressions
    diagnostics: ca.Function  # (S, p) -> (safety residuals, barriers (slots, N+1), clf residuals)


@lru_cache(maxsize=64)
def sx_problem(config: NMPCConfig) -> SXProblem:
    """Formulate the OCP symbolically once per configuration (cached)."""
    layout = layout_for(config)
    n = layout.horizon
    w = ca.SX.sym("S", layout.n_decision)
    p = ca.SX.sym("p", layout.n_parameters)
    i = STATE_DIM * (n + 1)
    j = i + CONTROL_DIM * n
    decay = w[j + n : j + 2 * n] if layout.has_decay_slack else ca.SX.ones(n)
    sym = OCPSymbols(
        states=ca.reshape(w[:i], STATE_DIM, n + 1),
        controls=ca.reshape(w[i:j], CONTROL_DIM, n),
        clf_slack=w[j : j + n],
        decay_slack=decay,
        parameters=p,
    )
    expr = formulate(config, sym, layout)
    diagnostics = ca.Function(
        "diagnostics",
        [w, p],
        [expr.safety, expr.barriers, expr.clf],
        ["S", "p"],
        ["safety", "barriers", "clf"],
    )
    return SXProblem(layout, w, p, expr, diagnostics)


@lru_cache(maxsize=64)
def paper_nlp(config: NMPCConfig) -> NLP:
    """g = [equalities == 0, clf >= 0, safety >= 0] with S's simple bounds (cached)."""
    problem = sx_problem(config)
    expr = problem.expressions
    g = ca.vertcat(expr.equalities, expr.clf, expr.safety)
    n_eq, n_ineq = expr.equalities.numel(), expr.clf.numel() + expr.safety.numel()
    lbg = np.zeros(n_eq + n_ineq)
    ubg = np.concatenate([np.zeros(n_eq), np.full(n_ineq, INF)])
    lbx, ubx = decision_bounds(config, problem.layout)
    nlp = {"x": problem.decision, "p": problem.parameters, "f": expr.cost, "g": g}
    return NLP("nmpc", nlp, (lbx, ubx, lbg, ubg), problem.layout.stages(), redundant_bounds(config, problem))


def redundant_bounds(config: NMPCConfig, problem: SXProblem) -> tuple[RedundantBounds, ...]:
    """The slacks' bounds that never decide the optimum (NLP.redundant):
    - s_v >= 0, always: s_v < 0 only tightens the CLF row and costs W1 s_v^2, and at a KKT point
      2 W1 s_v = lambda_clf >= 0;
    - Relax-CBF's s_h <= 1 while every obstacle's barrier at the measured state is positive: then
      B(k+1) >= s_h (1 - gamma) B(k) with s_h >= 0 keeps every predicted B(k) >= 0, an s_h above 1
      only tightens the row and costs more, and at a KKT point 2 W2 (s_h - 1) = -sum lambda
      (1 - gamma) B(k) <= 0. Inside an obstacle's set the bound matters (controllers.constraints).
    """
    layout = problem.layout
    n = layout.horizon

    def entries(clf_slack: np.ndarray, decay_slack: np.ndarray) -> tuple[int, ...]:
        """Where the marked slacks lie in S (read off the layout, as decision_bounds does)."""
        marked = Plan(np.zeros((n + 1, STATE_DIM)), np.zeros((n, CONTROL_DIM)), clf_slack, decay_slack)
        return tuple(int(i) for i in np.flatnonzero(marked.to_vector(layout)))

    bounds = [RedundantBounds(entries(np.ones(n), np.zeros(n)), "lower", ca.SX(1.0))]
    if layout.has_decay_slack:
        par = split_parameters(problem.parameters, layout)
        position = par["feedback"][:2]
        barriers = [
            barrier(position, centre[:, 0], config.robot_radius_m + radius)
            for centre, radius in zip(par["centres"], par["radii"], strict=True)
        ]
        holds = ca.mmin(ca.vertcat(*barriers)) if barriers else ca.SX(1.0)
        bounds.append(RedundantBounds(entries(np.zeros(n), np.ones(n)), "upper", holds))
    return tuple(bounds)
