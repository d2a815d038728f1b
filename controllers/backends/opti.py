"""The naive baseline: the paper's OCP declared with `casadi.Opti` (MX) and re-solved every step
with `set_value` / `set_initial` / `solve`, as most published CasADi NMPC code does. For the
benchmark's comparison only; no controller uses it unless told to."""

from __future__ import annotations

import casadi as ca
import numpy as np

from controllers.backends.ipopt import ipopt_options
from controllers.backends.nlp import RawSolution, from_stats
from controllers.config import NMPCConfig
from controllers.model import CONTROL_DIM, STATE_DIM
from controllers.ocp import OCPSymbols, formulate, layout_for


class OptiSolver:
    """The paper's OCP through casadi.Opti; solve(parameters, guess) like every backend."""

    name = "opti"
    pure = False  # the Opti object's state between solves is CasADi's; not relied on

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
        return from_stats(decision, stats, self.name)
