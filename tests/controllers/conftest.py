"""Fixtures shared by the controller tests."""

import numpy as np
import pytest

from controllers.backends import FatropSolver
from controllers.backends.nlp import RawSolution


@pytest.fixture
def fatrop_solves(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Counts the FATROP solves that really run (`["n"]`), whichever controller asks for them."""
    calls = {"n": 0}
    solve = FatropSolver.solve_without_fallback  # every FATROP run, with a fallback or without

    def counted(self: FatropSolver, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        calls["n"] += 1
        return solve(self, parameters, guess)

    monkeypatch.setattr(FatropSolver, "solve_without_fallback", counted)
    return calls
