"""The reference solver: IPOPT through CasADi's `nlpsol`, built once per NLP.

Any OCP (the paper's, husky-cbf's) is solved from numeric parameter and initial-guess vectors;
a failed solve is reported in the RawSolution, never raised. It is the structured solver's
automatic fallback and the reference the benchmark compares every backend with.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from controllers.backends.nlp import NLP, RawSolution, from_stats
from controllers.config import SolverOptions


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
    `warm_start=False` builds the cold one only (the structured solver's fallback, which always
    starts cold, so that its answer depends on the problem alone).
    """

    name = "ipopt"
    pure = False  # a solve after a success is warm-started from its multipliers

    def __init__(self, nlp: NLP, options: SolverOptions, warm_start: bool = True) -> None:
        self._bounds = dict(zip(("lbx", "ubx", "lbg", "ubg"), nlp.bounds, strict=True))
        ipopt = ipopt_options(options)
        self._cold = ca.nlpsol(f"{nlp.name}_cold", "ipopt", nlp.problem, ipopt)
        self._warm = (
            ca.nlpsol(f"{nlp.name}_warm", "ipopt", nlp.problem, {**ipopt, **WARM_START_OPTIONS})
            if warm_start
            else None
        )
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
        result = from_stats(decision, solver.stats(), self.name)
        warm = result.success and self._warm is not None
        self._multipliers = {"lam_x0": out["lam_x"], "lam_g0": out["lam_g"]} if warm else None
        return result
