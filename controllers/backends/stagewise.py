"""Stage-wise transcription of a multiple-shooting NLP, for structure-exploiting solvers (FATROP).

An OCP is declared once (controllers.ocp, controllers.husky_cbf.ocp) as a plain NLP over a
decision vector S. A structured solver needs it reordered by stage, S' = [x_0, u_0, x_1, u_1, ...,
x_N], with every constraint row of stage k depending only on x_k and u_k, apart from the
dynamics gaps x_{k+1} - F(x_k, u_k) = 0. This module derives that form from the declared NLP:

- the gap rows are the equality rows that are x_{k+1} - F(x_k, u_k) (unit coefficient on x_{k+1});
- every other row is put at the earliest stage it touches; where it also reads x_{k+1} (the
  CLF's V(k+1), a barrier's B(k+1)), x_{k+1} is replaced by F(x_k, u_k) read off the gap rows.

On the feasible set (gaps closed) every substituted row equals the declared one, so the feasible
set and the optimum are the same; only the order and the dependency structure change. A row that
cannot be put on one stage (it reads x_{k+2}, or controls of two stages) is refused with its
index, so an OCP that is not stage-wise is never solved as if it were.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np


class NotStagewiseError(ValueError):
    """The NLP has a constraint that no single stage can hold."""


@dataclass(frozen=True)
class StageIndices:
    """Where each stage's state x_k (k = 0..N) and control u_k (k = 0..N-1) lie in S.

    A stage's "control" is every decision that belongs to that stage and is not propagated by
    the dynamics: inputs, and per-stage slacks such as s_v(k), s_h(k).
    """

    states: tuple[tuple[int, ...], ...]
    controls: tuple[tuple[int, ...], ...]

    @property
    def horizon(self) -> int:
        return len(self.controls)

    def order(self) -> np.ndarray:
        """Index into S of each entry of S' = [x_0, u_0, ..., x_{N-1}, u_{N-1}, x_N]."""
        parts: list[int] = []
        for k in range(self.horizon):
            parts += [*self.states[k], *self.controls[k]]
        parts += list(self.states[-1])
        return np.asarray(parts, dtype=int)


@dataclass(frozen=True)
class StagewiseNLP:
    """The NLP in stage order: S' = S[order], g' rows as listed in `rows` (declared indices)."""

    nlp: dict[str, ca.SX]
    order: np.ndarray  # S' = S[order]
    rows: np.ndarray  # g'[i] is (the stage-wise form of) g[rows[i]]
    equality: tuple[bool, ...]  # per row of g': an equality (lbg == ubg)

    def to_stage_order(self, vector: np.ndarray) -> np.ndarray:
        """A decision vector (guess, bounds) in S's order -> S' order."""
        return np.asarray(vector, dtype=float).reshape(-1)[self.order]

    def from_stage_order(self, vector: np.ndarray) -> np.ndarray:
        """A decision vector in S' order -> S's order."""
        out = np.empty(self.order.size)
        out[self.order] = np.asarray(vector, dtype=float).reshape(-1)
        return out

    def rows_to_stage_order(self, vector: np.ndarray) -> np.ndarray:
        """Constraint bounds in g's order -> g' order."""
        return np.asarray(vector, dtype=float).reshape(-1)[self.rows]


def _row_dependencies(g: ca.SX, w: ca.SX) -> list[np.ndarray]:
    """For each row of g, the indices of S it depends on (structural sparsity)."""
    sparsity = ca.jacobian_sparsity(g, w)
    rows, cols = sparsity.get_triplet()
    deps: list[list[int]] = [[] for _ in range(g.numel())]
    for r, c in zip(rows, cols, strict=True):
        deps[r].append(c)
    return [np.asarray(d, dtype=int) for d in deps]


def transcribe(
    nlp: dict[str, ca.SX],
    lbg: np.ndarray,
    ubg: np.ndarray,
    stages: StageIndices,
) -> StagewiseNLP:
    """The stage-wise form of `nlp` (keys x, p, f, g; SX) with constraint bounds lbg <= g <= ubg."""
    w, g = nlp["x"], nlp["g"]
    n, n_w = stages.horizon, w.numel()
    lbg, ubg = np.asarray(lbg, dtype=float), np.asarray(ubg, dtype=float)
    order = stages.order()
    if sorted(order.tolist()) != list(range(n_w)):
        raise NotStagewiseError("stages: every decision must belong to exactly one stage")
    state_stage = np.full(n_w, -1)
    control_stage = np.full(n_w, -1)
    for k, idx in enumerate(stages.states):
        state_stage[list(idx)] = k
    for k, idx in enumerate(stages.controls):
        control_stage[list(idx)] = k

    # Sort every row onto a stage; find each stage's dynamics gaps.
    gaps: list[dict[int, int]] = [{} for _ in range(n)]  # stage -> {state component: row}
    path: list[list[int]] = [[] for _ in range(n + 1)]
    lifted: set[int] = set()  # rows that read x_{k+1}: substitute F(x_k, u_k)
    for row, deps in enumerate(_row_dependencies(g, w)):
        xs = set(state_stage[deps[state_stage[deps] >= 0]].tolist())
        us = set(control_stage[deps[control_stage[deps] >= 0]].tolist())
        stage = min(xs | us, default=0)
        if not (us <= {stage} and xs <= {stage, stage + 1}):
            raise NotStagewiseError(
                f"constraint row {row}: reads states of stages {sorted(xs)} and controls of "
                f"stages {sorted(us)}; a stage-wise row may read only x_k, u_k and x_(k+1)"
            )
        if stage + 1 in xs:
            if lbg[row] == ubg[row] == 0.0 and stage < n and _is_gap(g[row], w, stages.states[stage + 1]):
                component = _gap_component(g[row], w, stages.states[stage + 1])
                if component not in gaps[stage]:
                    gaps[stage][component] = row
                    continue
            lifted.add(row)
        path[stage].append(row)

    nx = [len(s) for s in stages.states]
    dynamics: list[ca.SX] = []
    for k in range(n):
        if sorted(gaps[k]) != list(range(nx[k + 1])):
            raise NotStagewiseError(
                f"stage {k}: found gap rows for state components {sorted(gaps[k])} of x_{k + 1}; "
                f"need one x_(k+1) - F(x_k, u_k) = 0 row for each of its {nx[k + 1]} components"
            )
        gap = ca.vertcat(*[g[gaps[k][c]] for c in range(nx[k + 1])])
        x_next = ca.vertcat(*[w[i] for i in stages.states[k + 1]])
        dynamics.append(-ca.substitute(gap, x_next, ca.SX.zeros(x_next.shape)))

    rows: list[int] = []
    exprs: list[ca.SX] = []
    for k in range(n + 1):
        gap_rows = [gaps[k][c] for c in range(nx[k + 1])] if k < n else []
        rows += gap_rows
        exprs += [g[r] for r in gap_rows]
        needs = [r for r in path[k] if r in lifted]
        if needs:
            x_next = ca.vertcat(*[w[i] for i in stages.states[k + 1]])
            substituted = ca.substitute(ca.vertcat(*[g[r] for r in needs]), x_next, dynamics[k])
            by_row = dict(zip(needs, ca.vertsplit(substituted), strict=True))
        else:
            by_row = {}
        for r in path[k]:  # the declared order within a stage
            rows.append(r)
            exprs.append(by_row[r] if r in by_row else g[r])
    rows_arr = np.asarray(rows, dtype=int)
    equality = tuple(bool(lbg[r] == ubg[r]) for r in rows_arr)
    stage_nlp = {"x": w[order.tolist()], "p": nlp["p"], "f": nlp["f"], "g": ca.vertcat(*exprs)}
    return StagewiseNLP(stage_nlp, order, rows_arr, equality)


def _is_gap(row: ca.SX, w: ca.SX, next_state: Sequence[int]) -> bool:
    """Whether `row` is x_{k+1}[c] - F_c(x_k, u_k): affine in x_{k+1} with one unit coefficient."""
    x_next = ca.vertcat(*[w[i] for i in next_state])
    jac = ca.jacobian(row, x_next)
    if not jac.is_constant():  # depends on decisions or parameters: not a plain x_(k+1) - F row
        return False
    coeffs = np.asarray(ca.evalf(jac), dtype=float).reshape(-1)
    return int(np.sum(coeffs != 0.0)) == 1 and float(np.max(coeffs)) == 1.0


def _gap_component(row: ca.SX, w: ca.SX, next_state: Sequence[int]) -> int:
    x_next = ca.vertcat(*[w[i] for i in next_state])
    coeffs = np.asarray(ca.evalf(ca.jacobian(row, x_next)), dtype=float).reshape(-1)
    return int(np.argmax(coeffs))
