"""NLP solver backends: what solves an OCP, kept apart from what the OCP is (controllers.ocp).

- `fatrop`: FATROP on the stage-wise form, compiled to C, IPOPT as its fallback; one instance per
  problem in a process (controllers.backends.shared);
- `ipopt`: IPOPT through `nlpsol`, the reference (and the structured solver's fallback);
- `opti`: the paper's OCP through `casadi.Opti`, the naive baseline (benchmark only).
"""

from __future__ import annotations

from controllers.backends.fatrop import FatropSolver
from controllers.backends.ipopt import IpoptSolver
from controllers.backends.nlp import NLP, RawSolution
from controllers.backends.shared import shared_fatrop_solver
from controllers.config import SolverOptions

__all__ = ["NLP", "FatropSolver", "IpoptSolver", "RawSolution", "make_solver"]


def make_solver(
    nlp: NLP, options: SolverOptions, fallback_max_iter: int | None = None
) -> FatropSolver | IpoptSolver:
    """The solver `options.backend` names for any OCP given as an NLP (`opti` is the paper
    controller's own baseline, built from its configuration, not from an NLP); `fallback_max_iter`
    caps FATROP's IPOPT fallback (FatropSolver). A FATROP solver is shared by every caller that
    asks for the same problem in this process."""
    if options.backend == "fatrop":
        return shared_fatrop_solver(nlp, options, fallback_max_iter)
    if options.backend == "ipopt":
        return IpoptSolver(nlp, options)
    raise ValueError(f"solver.backend: {options.backend!r} cannot solve {nlp.name}; use fatrop or ipopt")
