"""Answers to the last control step's problems, for a step that poses them again bit for bit.

In a deterministic simulation a robot that stands still poses the same NLPs at every control step.
The paper's controllers deadlock in the kinematic loop: they brake, the brake leaves the unicycle's
state exactly as it was, and every step solves the same (parameters, guess) pairs again, the first
solve and each recovery guess, often each to its iteration cap (the claims report's Relax-CBF on
husky_point_stabilisation at N = 12 and 15: 800 capped FATROP and IPOPT solves per run). A solver
whose answer is a function of (parameters, guess) alone (`pure`: FatropSolver, whose IPOPT fallback
starts cold) gives the same answer again, so it is looked up instead of computed. Only the answers
of the current and the previous step are kept.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from controllers.backends.nlp import RawSolution


class RepeatedProblems:
    """(parameters, guess) -> RawSolution for the current and the previous control step."""

    def __init__(self) -> None:
        self._previous: dict[bytes, RawSolution] = {}
        self._current: dict[bytes, RawSolution] = {}

    def next_step(self) -> None:
        """A new control step: what the step before last solved is forgotten."""
        self._previous, self._current = self._current, {}

    def clear(self) -> None:
        self._previous, self._current = {}, {}

    def solve(
        self,
        solve: Callable[[np.ndarray, np.ndarray], RawSolution],
        parameters: np.ndarray,
        guess: np.ndarray,
        kind: bytes = b"",
    ) -> tuple[RawSolution, bool]:
        """solve(parameters, guess), or the answer it gave to the same bytes this step or the last;
        and whether it was looked up. `solve` must be pure; `kind` tells apart solves that answer
        the same problem differently (a solver with and without its fallback). An exception is
        not remembered."""
        key = kind + parameters.tobytes() + guess.tobytes()
        known = self._current.get(key, self._previous.get(key))
        repeated = known is not None
        if known is None:
            known = solve(parameters, guess)
        self._current[key] = known
        return replace(known, decision=known.decision.copy()), repeated
