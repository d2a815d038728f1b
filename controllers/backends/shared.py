"""One structured solver per problem in a process: controllers built for the same NLP share it.

A robustness sweep builds a controller for every episode, and its samples differ in the robot and
the world, not in the problem: husky-cbf's NLPs are the same for every sample of a check (its pose
filter's noise is not part of them). Building its two FATROP solvers took 0.22 s of CPU per episode
(generating C to find the compiled library in the cache, three `nlpsol` instances), a tenth of a
check's CPU time. A FatropSolver keeps nothing between solves (`pure`: the compiled solver holds
no state, its IPOPT fallback is reset before each use), so one instance serves every controller of
that problem in the process. IPOPT is never shared: it warm-starts from its last solve.

The key is a hash of the NLP's expressions (CasADi's serialisation of f, g and the redundant bounds'
conditions, which is the same for the same expressions built again), its bounds, stage layout and
name, the solver options and the fallback cap. The SHARED_SOLVERS most recently used are kept.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

import casadi as ca
import numpy as np

from controllers.backends.fatrop import FatropSolver
from controllers.backends.nlp import NLP
from controllers.config import SolverOptions

#: Solvers kept per process (a suite worker meets a new problem with almost every cell).
SHARED_SOLVERS = 8

_solvers: OrderedDict[str, FatropSolver] = OrderedDict()


def problem_key(nlp: NLP, options: SolverOptions, fallback_max_iter: int | None) -> str:
    """A hash of everything a FatropSolver is built from."""
    problem = nlp.problem
    outputs = [problem["f"], problem["g"], *(entry.holds for entry in nlp.redundant)]
    digest = hashlib.sha256(ca.Function("key", [problem["x"], problem["p"]], outputs).serialize().encode())
    for bound in nlp.bounds:
        digest.update(np.ascontiguousarray(bound, dtype=float).tobytes())
    layout = (nlp.name, nlp.stages, [(e.indices, e.side) for e in nlp.redundant], options, fallback_max_iter)
    digest.update(repr(layout).encode())
    return digest.hexdigest()


def shared_fatrop_solver(
    nlp: NLP, options: SolverOptions, fallback_max_iter: int | None = None
) -> FatropSolver:
    """The process's FatropSolver for this problem, built on first use."""
    key = problem_key(nlp, options, fallback_max_iter)
    solver = _solvers.get(key)
    if solver is None:
        solver = FatropSolver(nlp, options, fallback_max_iter)
        _solvers[key] = solver
        while len(_solvers) > SHARED_SOLVERS:
            _solvers.popitem(last=False)
    _solvers.move_to_end(key)
    return solver


def forget_shared_solvers() -> None:
    """Drop every shared solver (the next controller builds its own again)."""
    _solvers.clear()
