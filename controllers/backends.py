"""Solver backends for the OCP: ours (`nlpsol`, built once per configuration) and the naive
`casadi.Opti` baseline that most published CasADi code uses (benchmark comparison only).

Both take the numeric parameter and initial-guess vectors of controllers.ocp and return the
decision vector with IPOPT's status; neither raises on a failed solve.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.config import NMPCConfig, SolverOptions
from controllers.model import CONTROL_DIM, STATE_DIM
from controllers.ocp import (
    OCPExpressions,
    OCPLayout,
    OCPSymbols,
    decision_bounds,
    formulate,
    layout_for,
)


@dataclass
class RawSolution:
    """What a backend returns: the decision vector and IPOPT's verdict."""

    decision: np.ndarray
    success: bool
    status: str
    iterations: int


def ipopt_options(options: SolverOptions) -> dict[str, object]:
    """Quiet IPOPT with the configured tolerances; failures are reported, never raised."""
    return {
        "print_time": False,
        "error_on_fail": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": options.max_iter,
        "ipopt.tol": options.tol,
        "ipopt.acceptable_tol": options.acceptable_tol,
        "ipopt.constr_viol_tol": options.constr_viol_tol,
        "ipopt.max_wall_time": options.max_wall_time_s,
    }


def _finish(decision: np.ndarray, stats: dict) -> RawSolution:
    status = str(stats.get("return_status", "unknown"))
    success = bool(stats.get("success", False)) and bool(np.all(np.isfinite(decision)))
    if not np.all(np.isfinite(decision)):
        status = f"{status} (non-finite solution)"
    return RawSolution(decision, success, status, int(stats.get("iter_count", -1)))


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


#: IPOPT settings for a primal-dual warm start from the previous solve's multipliers, with a
#: small initial barrier parameter so that IPOPT does not push a good guess back into the
#: interior. Measured here (relax-cbf, N = 5, 7 obstacles, `husky-sim bench`): median solve time
#: 6.2 -> 4.2 ms. Smaller mu_init (1e-5) was faster still but changed which local optimum the
#: closed loop settles in (relax-cbf N = 12 then deadlocked in the paper's problem).
WARM_START_OPTIONS = {
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-3,
    "ipopt.warm_start_bound_push": 1e-4,
    "ipopt.warm_start_mult_bound_push": 1e-4,
}


class IpoptSolver:
    """One NLP solved by IPOPT through `nlpsol`, built once; a solve is one function call.

    Two solvers share the NLP: a cold one (IPOPT defaults) for the first solve and after a
    failure or `reset`, and a warm one seeded with the last successful solve's multipliers.
    """

    def __init__(
        self,
        name: str,
        nlp: dict[str, ca.SX],
        bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        options: SolverOptions,
    ) -> None:
        self._bounds = dict(zip(("lbx", "ubx", "lbg", "ubg"), bounds, strict=True))
        ipopt = ipopt_options(options)
        self._cold = ca.nlpsol(f"{name}_cold", "ipopt", nlp, ipopt)
        self._warm = ca.nlpsol(f"{name}_warm", "ipopt", nlp, {**ipopt, **WARM_START_OPTIONS})
        self._multipliers: dict[str, ca.DM] | None = None

    def reset(self) -> None:
        """Forget the multipliers (next solve is cold)."""
        self._multipliers = None

    def solve(self, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        if self._multipliers is None:
            solver, out = self._cold, self._cold(x0=guess, p=parameters, **self._bounds)
        else:
            solver = self._warm
            out = solver(x0=guess, p=parameters, **self._bounds, **self._multipliers)
        decision = np.asarray(out["x"], dtype=float).reshape(-1)
        result = _finish(decision, solver.stats())
        self._multipliers = {"lam_x0": out["lam_x"], "lam_g0": out["lam_g"]} if result.success else None
        return result


class NlpsolBackend:
    """The paper's OCP solved by IPOPT through `nlpsol` (IpoptSolver), built once per configuration."""

    name = "nlpsol"

    def __init__(self, config: NMPCConfig) -> None:
        problem = sx_problem(config)
        self.layout = problem.layout
        expr = problem.expressions
        g = ca.vertcat(expr.equalities, expr.clf, expr.safety)
        n_eq, n_ineq = expr.equalities.numel(), expr.clf.numel() + expr.safety.numel()
        lbg = np.concatenate([np.zeros(n_eq), np.zeros(n_ineq)])
        ubg = np.concatenate([np.zeros(n_eq), np.full(n_ineq, np.inf)])
        lbx, ubx = decision_bounds(config, self.layout)
        nlp = {"x": problem.decision, "p": problem.parameters, "f": expr.cost, "g": g}
        self._solver = IpoptSolver("nmpc", nlp, (lbx, ubx, lbg, ubg), config.solver)

    def reset(self) -> None:
        """Forget the multipliers (next solve is cold)."""
        self._solver.reset()

    def solve(self, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        return self._solver.solve(parameters, guess)


class OptiBackend:
    """Naive baseline: the same OCP declared with `casadi.Opti` (MX), re-solved every step with
    `set_value`/`set_initial`/`solve`, as most published CasADi NMPC code does."""

    name = "opti"

    def __init__(self, config: NMPCConfig) -> None:
        self.layout = layout = layout_for(config)
        n = layout.horizon
        opti = ca.Opti()
        x = opti.variable(STATE_DIM, n + 1)
        u = opti.variable(CONTROL_DIM, n)
        s_v = opti.variable(n)
        s_h = opti.variable(n) if layout.has_decay_slack else ca.MX.ones(n)
        p = opti.parameter(layout.n_parameters)
        expr = formulate(config, OCPSymbols(x, u, s_v, s_h, p), layout)
        opti.minimize(expr.cost)
        opti.subject_to(expr.equalities == 0)
        opti.subject_to(expr.clf >= 0)
        if expr.safety.numel():
            opti.subject_to(expr.safety >= 0)
        opti.subject_to(opti.bounded(config.v_min_mps, u[0, :], config.v_max_mps))
        opti.subject_to(opti.bounded(-config.omega_max_radps, u[1, :], config.omega_max_radps))
        opti.subject_to(s_v >= 0)
        if layout.has_decay_slack:
            opti.subject_to(opti.bounded(0, s_h, 1))
        opti.solver("ipopt", ipopt_options(config.solver))
        self._opti, self._p = opti, p
        self._variables = [x, u, s_v] + ([s_h] if layout.has_decay_slack else [])

    def reset(self) -> None:
        """Nothing to forget: the naive baseline warm-starts only the primal guess."""

    def _vector_of(self, values: object) -> np.ndarray:
        return np.concatenate([np.asarray(values(v), dtype=float).T.ravel() for v in self._variables])

    def solve(self, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        opti, n = self._opti, self.layout.horizon
        opti.set_value(self._p, parameters)
        sizes = [STATE_DIM * (n + 1), CONTROL_DIM * n, n, n]
        offset = 0
        for var, size in zip(self._variables, sizes, strict=False):
            chunk = guess[offset : offset + size]
            offset += size
            rows = var.size1()
            opti.set_initial(var, chunk.reshape(-1, rows).T if rows > 1 and var.size2() > 1 else chunk)
        try:
            sol = opti.solve()
            decision, stats = self._vector_of(sol.value), sol.stats()
        except RuntimeError:
            decision, stats = self._vector_of(opti.debug.value), opti.stats()
        return _finish(decision, stats)


BACKENDS = {"nlpsol": NlpsolBackend, "opti": OptiBackend}
