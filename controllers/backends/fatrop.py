"""The structured solver: FATROP on the stage-wise form of the OCP, compiled to C, with IPOPT as its
automatic fallback.

FATROP (an interior-point method that factorises the KKT system stage by stage with a Riccati
recursion) ships inside CasADi. The NLP is transcribed stage-wise (controllers.backends.stagewise),
the whole solver is generated as C and compiled once per configuration (controllers.backends.
compiled), and each solve is one call of the compiled function.

A FATROP solve is accepted only if it returned (no iteration cap, no solver error), its decision
is finite and every constraint holds to `CONSTRAINT_CHECK_TOL`. Otherwise the same problem is
solved by the reference IpoptSolver (built on first need) from the same guess, and the solution
says why (`fallback_reason`), so that every fallback is counted and logged by the controller.
The fallback solves cold (no multipliers carried over), so its answer depends only on the problem
and the guess.

Not the default yet: on these OCPs FATROP stalls on part of the problems at N = 12 (and for BT
and CBF at N = 5): the primal converges, then as the barrier parameter falls the dual
infeasibility stops decreasing under heavy Hessian regularisation, toward a point IPOPT does not
go to (README, "Solver backends").
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from controllers.backends.compiled import compiled
from controllers.backends.ipopt import IpoptSolver
from controllers.backends.nlp import NLP, RawSolution
from controllers.backends.stagewise import transcribe
from controllers.config import SolverOptions

#: A FATROP solution whose constraints are violated by more than this (m, m^2, rad) is refused.
CONSTRAINT_CHECK_TOL = 1e-6


def fatrop_options(options: SolverOptions, equality: tuple[bool, ...]) -> dict[str, object]:
    """Quiet FATROP with the configured tolerance; a failure raises in the compiled function."""
    return {
        "structure_detection": "auto",
        "equality": list(equality),
        "expand": True,
        "print_time": False,
        "error_on_fail": True,
        "fatrop.print_level": 0,
        "fatrop.max_iter": options.max_iter,
        "fatrop.tol": options.tol,
    }


class FatropSolver:
    """One NLP solved by compiled FATROP, falling back to IPOPT; a solve is one function call."""

    name = "fatrop"

    def __init__(self, nlp: NLP, options: SolverOptions) -> None:
        self._nlp, self._options = nlp, options
        lbx, ubx, lbg, ubg = nlp.bounds
        self._stagewise = stagewise = transcribe(nlp.problem, lbg, ubg, nlp.stages)
        lbx, ubx = stagewise.to_stage_order(lbx), stagewise.to_stage_order(ubx)
        lbg, ubg = stagewise.rows_to_stage_order(lbg), stagewise.rows_to_stage_order(ubg)
        # the bounds as CasADi passes them (converted once, not on every call) and, for the
        # constraint check, only the finite ones: (indices, values) per side
        self._bounds = {k: ca.DM(v) for k, v in (("lbx", lbx), ("ubx", ubx), ("lbg", lbg), ("ubg", ubg))}
        self._finite = {
            k: (np.flatnonzero(np.isfinite(v)), v[np.isfinite(v)])
            for k, v in (("lbx", lbx), ("ubx", ubx), ("lbg", lbg), ("ubg", ubg))
        }
        solver = ca.nlpsol(nlp.name, "fatrop", stagewise.nlp, fatrop_options(options, stagewise.equality))
        self._function = compiled(solver)
        self._reference: IpoptSolver | None = None

    def reset(self) -> None:
        """Nothing is carried between solves but the guess."""

    def _refused(self, x: np.ndarray, g: np.ndarray) -> str:
        """Why a returned FATROP solution (x, g in stage order) is not accepted ("" if it is)."""
        if not (np.isfinite(x).all() and np.isfinite(g).all()):
            return "non-finite solution"
        f = self._finite
        violation = max(
            np.max(f["lbg"][1] - g[f["lbg"][0]], initial=0.0),
            np.max(g[f["ubg"][0]] - f["ubg"][1], initial=0.0),
            np.max(f["lbx"][1] - x[f["lbx"][0]], initial=0.0),
            np.max(x[f["ubx"][0]] - f["ubx"][1], initial=0.0),
        )
        if violation > CONSTRAINT_CHECK_TOL:
            return f"constraint check: violation {violation:.2g}"
        return ""

    def solve(self, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        stagewise = self._stagewise
        try:
            out = self._function(x0=stagewise.to_stage_order(guess), p=parameters, **self._bounds)
        except RuntimeError:
            reason = "did not converge (iteration cap or solver error)"
        else:
            x, g = out["x"].full().ravel(), out["g"].full().ravel()
            reason = self._refused(x, g)
            if not reason:
                return RawSolution(stagewise.from_stage_order(x), True, "Solve_Succeeded", -1, self.name)
        if self._reference is None:
            self._reference = IpoptSolver(self._nlp, self._options)
        self._reference.reset()
        fallback = self._reference.solve(parameters, guess)
        fallback.fallback_reason = f"fatrop: {reason}"
        return fallback
