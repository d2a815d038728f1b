"""What a solver backend is given (an NLP with bounds and stage structure) and returns."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from controllers.backends.stagewise import StageIndices


@dataclass(frozen=True)
class NLP:
    """One OCP as an NLP: min f(S; p) s.t. lbg <= g(S; p) <= ubg, lbx <= S <= ubx.

    `stages` says where x_k and u_k lie in S, for solvers that exploit the stage structure.
    """

    name: str
    problem: dict[str, ca.SX]  # keys x, p, f, g
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # lbx, ubx, lbg, ubg
    stages: StageIndices


@dataclass
class RawSolution:
    """The decision vector (in the OCP's declared order) and the solver's verdict.

    `solver` names the solver whose answer this is; `fallback_reason` is set when the structured
    solver failed and the reference IPOPT solved instead (why the structured one was not used).
    """

    decision: np.ndarray
    success: bool
    status: str
    iterations: int  # -1 where the solver does not report it (a compiled solver)
    solver: str = ""
    fallback_reason: str = ""


def from_stats(decision: np.ndarray, stats: dict, solver: str) -> RawSolution:
    """A RawSolution from a CasADi nlpsol's stats(); a non-finite decision is never a success."""
    status = str(stats.get("return_status", "unknown"))
    finite = bool(np.all(np.isfinite(decision)))
    if not finite:
        status = f"{status} (non-finite solution)"
    success = bool(stats.get("success", False)) and finite
    return RawSolution(decision, success, status, int(stats.get("iter_count", -1)), solver)
