"""The structured solver: FATROP on the stage-wise form of the OCP, compiled to C, with IPOPT as its
automatic fallback. The default backend.

FATROP (an interior-point method that factorises the KKT system stage by stage with a Riccati
recursion) ships inside CasADi. The NLP is transcribed stage-wise (controllers.backends.stagewise),
and one function is generated as C and compiled once per configuration (controllers.backends.
compiled): it scales the objective, calls FATROP and returns the solution, so each solve is one
call of compiled code. The bounds are its inputs, so configurations that differ only in bounds
share one compiled solver. Its status shim tells which exit FATROP took.

Three decisions make FATROP converge on these problems rather than stall at its barrier floor
(docs/solvers.md):
- **Objective scaling per solve**, as IPOPT's gradient-based scaling does, but to a largest
  gradient entry of GRADIENT_SCALE (IPOPT: 100) at the guess. Unscaled, FATROP's absolute dual
  tolerance on objectives of 1e3 to 1e5 asked for more than its Riccati factorisation delivers
  once the barrier parameter is small: the primal converged, then every step needed Hessian
  regularisation of 1e2 to 1e4 and the dual infeasibility stopped falling until the iteration
  cap, and on Relax-CBF N = 12 it settled near a point IPOPT does not go to.
- **FATROP's acceptable exit is accepted**: ACCEPTABLE_TOL held for ACCEPTABLE_ITER consecutive
  iterations (IPOPT's own rule, with IPOPT's default tolerance class) ends a solve that has
  stopped improving, instead of running it into the cap.
- **Redundant bounds are loosened** (NLP.redundant): a slack whose cost is smallest on its bound
  (s_v >= 0, Relax-CBF's s_h <= 1) sits there with a zero multiplier wherever its constraint is
  slack, and on such a degenerate bound FATROP stalled once its barrier parameter reached its
  floor. While a bound is redundant (it never decides the optimum) FATROP gets it moved by
  REDUNDANT_BOUND_SLACK, and its answer is put back on the declared bound.

A FATROP solve is accepted only if its exit flag is one of ACCEPTED_EXITS, its decision is finite
and every constraint holds to CONSTRAINT_CHECK_TOL. Otherwise the same problem is solved by the
reference IpoptSolver (built on the first fallback) from the same guess, cold, so its answer
depends only on the problem and the guess, and the solution says why (`fallback_reason`: the
exit flag and iteration count), so that every fallback is counted and logged by the controller.
`solve_without_fallback` is FATROP alone: the paper controllers' retries from their recovery
guesses (controllers.nmpc), where IPOPT's cold verdicts only cost time.
Without a C compiler the function runs uncompiled: FATROP's exit flag is then not visible, so only
a converged solve is accepted and its acceptable exits go to IPOPT.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import casadi as ca
import numpy as np

from controllers.backends.compiled import FatropStatus, compiled_library
from controllers.backends.ipopt import IpoptSolver
from controllers.backends.nlp import NLP, RawSolution
from controllers.backends.stagewise import transcribe
from controllers.config import SolverOptions

#: A FATROP solution whose constraints are violated by more than this (m, m^2, rad) is refused.
CONSTRAINT_CHECK_TOL = 1e-6
#: The objective is multiplied by min(1, GRADIENT_SCALE / max|grad f(guess)|). Measured on the
#: bench's recorded problems (bt, cbf, relax-cbf; N = 5 and 12; 7 obstacles): 100 (IPOPT's
#: default) left 1 to 23 stalled problems per cell, 10 none, with first controls within 1e-4 of
#: converged IPOPT on at least 99 % of every cell but BT N = 12.
GRADIENT_SCALE = 10.0
#: FATROP's acceptable exit: this overall error (on the scaled problem) for ACCEPTABLE_ITER
#: consecutive iterations. 1e-4 / 5 measured best of 1e-3, 1e-4, 1e-5 and 3, 5, 10, 15.
ACCEPTABLE_TOL = 1e-4
ACCEPTABLE_ITER = 5
#: While an NLP's bounds are redundant (NLP.redundant: s_v >= 0 always, Relax-CBF's s_h <= 1 while
#: every obstacle's barrier at the measured state is positive) FATROP gets them moved outward by
#: this. On such a bound, where the cost puts the slack whenever its constraint is slack, the
#: multiplier is zero (strict complementarity fails) and FATROP stalled: once its barrier
#: parameter reached its floor, each step needed Hessian regularisation of 1e1 to 1e2 and the
#: dual infeasibility stayed near 3e-4 until the iteration cap, where IPOPT converges in 15
#: iterations. Any move keeps the minimisers. Measured over the 84 PyBullet cells of the scenario
#: table, FATROP's own failures (steps whose problem IPOPT then solved from the same guess) were
#: 159 with the bounds; s_h's raised by 0.25 / 0.5 / 1 / without bound: 63 / 62 / 78 / 100 (an
#: unbounded s_h wanders off where an infeasible iterate's B(k) < 0 rewards it); with s_v's
#: lowered by 0.5 as well: 58.
REDUNDANT_BOUND_SLACK = 0.5
#: FATROP exits whose solution is used (if it also passes the constraint check).
ACCEPTED_EXITS = frozenset({"Success", "StopAtAcceptablePoint"})


def fatrop_options(options: SolverOptions, equality: tuple[bool, ...]) -> dict[str, object]:
    """Quiet FATROP with the configured tolerance and its acceptable exit. Uncompiled, a solve
    that did not converge raises; compiled, the status shim reports every exit instead."""
    return {
        "structure_detection": "auto",
        "equality": list(equality),
        "expand": True,
        "print_time": False,
        "error_on_fail": True,
        "fatrop.print_level": 0,
        "fatrop.max_iter": options.max_iter,
        "fatrop.tol": options.tol,
        "fatrop.tol_acceptable": ACCEPTABLE_TOL,
        "fatrop.acceptable_iter": ACCEPTABLE_ITER,
    }


def scaled_solve_function(
    name: str,
    nlp: dict[str, ca.SX],
    options: dict[str, object],
    loosened: Sequence[tuple[np.ndarray, ca.SX]] = (),
) -> ca.Function:
    """(x0, p, lbx, ubx, lbg, ubg) -> (x, g): FATROP on sigma * f with
    sigma = min(1, GRADIENT_SCALE / max|grad f(x0)|). The bounds stay inputs, so that problems
    that differ only in their bounds (a check's sampled drive limits) share one compiled solver.
    `loosened`: (signed mask over x, condition in p) pairs; while a condition is > 0, its masked
    bounds move away from S by REDUNDANT_BOUND_SLACK (-1: lower bounds, +1: upper; NLP.redundant)."""
    x, p, f = nlp["x"], nlp["p"], nlp["f"]
    sigma = ca.SX.sym("sigma")
    scaled = {**nlp, "p": ca.vertcat(p, sigma), "f": sigma * f}
    solver = ca.nlpsol(f"{name}_inner", "fatrop", scaled, options)
    gradient = ca.Function(f"{name}_gradient", [x, p], [ca.gradient(f, x)])
    guess, parameters = ca.MX.sym("x0", x.numel()), ca.MX.sym("p", p.numel())
    bounds = {k: ca.MX.sym(k, n) for k, n in (("lbx", x.numel()), ("ubx", x.numel()))}
    bounds |= {k: ca.MX.sym(k, nlp["g"].numel()) for k in ("lbg", "ubg")}
    largest = ca.mmax(ca.fabs(gradient(guess, parameters)))
    scale = ca.fmin(1.0, GRADIENT_SCALE / ca.fmax(largest, 1e-300))
    inputs = {"x0": guess, "p": parameters, **bounds}
    for i, (signs, condition) in enumerate(loosened):
        holds = ca.Function(f"{name}_redundant_{i}", [p], [condition])(parameters) > 0
        shift = ca.if_else(holds, ca.DM(REDUNDANT_BOUND_SLACK * signs), ca.DM.zeros(x.numel()))
        bounds = {
            **bounds,
            "lbx": bounds["lbx"] + ca.fmin(shift, 0),
            "ubx": bounds["ubx"] + ca.fmax(shift, 0),
        }
    out = solver(x0=guess, p=ca.vertcat(parameters, scale), **bounds)
    return ca.Function(name, list(inputs.values()), [out["x"], out["g"]], list(inputs), ["x", "g"])


class FatropSolver:
    """One NLP solved by compiled FATROP, falling back to IPOPT; a solve is one function call."""

    name = "fatrop"
    #: A solve's answer is a function of (parameters, guess) alone: the compiled solver keeps
    #: nothing between calls, and the IPOPT fallback starts cold (controllers.backends.repeats).
    pure = True

    def __init__(self, nlp: NLP, options: SolverOptions, fallback_max_iter: int | None = None) -> None:
        lbx, ubx, lbg, ubg = nlp.bounds
        self._stagewise = stagewise = transcribe(nlp.problem, lbg, ubg, nlp.stages)
        bounds = {
            "lbx": stagewise.to_stage_order(lbx),
            "ubx": stagewise.to_stage_order(ubx),
            "lbg": stagewise.rows_to_stage_order(lbg),
            "ubg": stagewise.rows_to_stage_order(ubg),
        }
        # the bounds as CasADi takes them (converted once, not on every call) and, for the
        # constraint check, only the finite ones: (indices, values) per side
        self._bounds = {k: ca.DM(v) for k, v in bounds.items()}
        self._finite = {k: (np.flatnonzero(np.isfinite(v)), v[np.isfinite(v)]) for k, v in bounds.items()}
        # the redundant bounds, loosened while they are redundant: a solve may then end a hair
        # beyond one (an approximate s_h = 1 + 1e-5); its answer is put back on the declared
        # bound, which (the bound being redundant) only loosens the constraint rows it enters
        loosened, redundant = [], np.zeros(lbx.size, dtype=bool)
        for entry in nlp.redundant:
            signs = np.zeros(lbx.size)
            signs[list(entry.indices)] = -1.0 if entry.side == "lower" else 1.0
            signs = stagewise.to_stage_order(signs)
            loosened.append((signs, entry.holds))
            redundant |= signs != 0
        clipped = np.flatnonzero(redundant)
        self._clip = (clipped, bounds["lbx"][clipped], bounds["ubx"][clipped])
        function = scaled_solve_function(
            f"{nlp.name}_fatrop", stagewise.nlp, fatrop_options(options, stagewise.equality), loosened
        )
        library = compiled_library(function)
        self._function = function if library is None else ca.external(function.name(), str(library))
        # called positionally (x0, p, then the bounds): CasADi's keyword call costs ~40 us
        names = self._function.name_in()
        assert names[:2] == ["x0", "p"], names
        self._bound_args = [self._bounds[name] for name in names[2:]]
        self._status = None if library is None else FatropStatus(library)
        # fallback_max_iter caps the fallback IPOPT (default: options.max_iter; 0: no fallback),
        # for a caller whose own next step after a failure is cheaper than IPOPT's full verdict
        # (husky-cbf's hard problem, followed by its exact-penalty re-solve)
        self._falls_back = fallback_max_iter != 0
        fallback = options if not fallback_max_iter else replace(options, max_iter=fallback_max_iter)
        # built on the first fallback: most controllers never fall back, and building IPOPT costs
        # about 9 ms of CPU, a quarter of a paper controller's build
        self._reference_problem = (nlp, fallback)
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
        """FATROP's answer, or where it is refused, the reference IPOPT's from the same guess
        (unless built with fallback_max_iter=0)."""
        raw = self.solve_without_fallback(parameters, guess)
        return raw if raw.success or not self._falls_back else self._fall_back(parameters, guess, raw.status)

    def solve_without_fallback(self, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        """FATROP's answer alone: a refused one comes back failed (decision: the guess), its status
        saying why (the exit flag and iterations, or the check it failed)."""
        stagewise = self._stagewise
        iterations = -1
        if not (np.isfinite(parameters).all() and np.isfinite(guess).all()):
            # FATROP does not check its inputs: a NaN makes its regularisation loop spin forever
            return RawSolution(guess, False, "non-finite parameters or guess", iterations, self.name)
        try:
            x, g = self._function.call([stagewise.to_stage_order(guess), parameters, *self._bound_args])
        except RuntimeError:
            reason = "solver error" if self._status is not None else "did not converge (uncompiled)"
        else:
            exit_flag, iterations = self._status.last() if self._status is not None else ("Success", -1)
            if exit_flag in ACCEPTED_EXITS:
                x, g = x.full().ravel(), g.full().ravel()
                clipped, lower, upper = self._clip
                x[clipped] = np.clip(x[clipped], lower, upper)
                reason = self._refused(x, g)
                if not reason:
                    status = "Solve_Succeeded" if exit_flag == "Success" else "Solved_To_Acceptable_Level"
                    return RawSolution(stagewise.from_stage_order(x), True, status, iterations, self.name)
            else:
                reason = f"{exit_flag} after {iterations} iterations"
        return RawSolution(guess, False, reason, iterations, self.name)

    def _fall_back(self, parameters: np.ndarray, guess: np.ndarray, reason: str) -> RawSolution:
        """The reference IPOPT's answer to the same problem, cold, saying why FATROP's was not used."""
        if self._reference is None:
            self._reference = IpoptSolver(*self._reference_problem, warm_start=False)
        self._reference.reset()
        fallback = self._reference.solve(parameters, guess)
        fallback.fallback_reason = f"fatrop: {reason}"
        return fallback
