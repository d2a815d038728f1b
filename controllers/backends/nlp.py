"""What a solver backend is given (an NLP with bounds and stage structure) and returns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np

from controllers.backends.stagewise import StageIndices


@dataclass(frozen=True)
class RedundantBounds:
    """Bounds on S (all lower or all upper) that are redundant while `holds`, a scalar expression
    in p alone, is > 0: no local minimiser and no KKT point of the problem without them lies
    beyond them, so dropping them changes neither. What they cost is degeneracy: a slack whose
    cost is smallest on its bound (W1 s_v^2 at s_v = 0, W2 (s_h - 1)^2 at s_h = 1) sits on it with
    a zero multiplier wherever its constraint is slack, where strict complementarity fails and
    an interior-point method may stall (controllers.backends.fatrop).
    """

    indices: tuple[int, ...]  # into S
    side: Literal["lower", "upper"]
    holds: ca.SX  # scalar in p; the bounds are redundant while it is > 0 (a constant: always)


@dataclass(frozen=True)
class NLP:
    """One OCP as an NLP: min f(S; p) s.t. lbg <= g(S; p) <= ubg, lbx <= S <= ubx.

    `stages` says where x_k and u_k lie in S, for solvers that exploit the stage structure.
    `redundant` names bounds a solver may loosen while a condition on p holds; the declared
    bounds stay the problem (solutions are checked against them, and IPOPT keeps them).
    """

    name: str
    problem: dict[str, ca.SX]  # keys x, p, f, g
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # lbx, ubx, lbg, ubg
    stages: StageIndices
    redundant: tuple[RedundantBounds, ...] = ()


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
