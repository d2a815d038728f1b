"""The paper's BT, CBF and Relax-CBF controllers are ours to reproduce, not to improve: their
kinematic closed-loop outputs are pinned bit for bit (tests/controllers/paper_kinematic_runs.py), so that
husky-cbf and the shared solver fallback can never change them unnoticed."""

import numpy as np
import pytest

from tests.controllers.paper_kinematic_runs import CASES, REFERENCE_FILE, case_key, run_case

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    with np.load(REFERENCE_FILE) as data:
        return dict(data)


@pytest.mark.parametrize(("problem", "variant", "horizon"), CASES)
def test_paper_controllers_bit_identical(
    reference: dict[str, np.ndarray], problem: str, variant: str, horizon: int
) -> None:
    out = run_case(problem, variant, horizon)
    key = case_key(problem, variant, horizon)
    for name, value in out.items():
        pinned = reference[f"{key}__{name}"]
        assert value.shape == pinned.shape, f"{name}: {value.shape} != {pinned.shape}"
        differs = np.flatnonzero(value.ravel() != pinned.ravel())
        assert differs.size == 0, (
            f"{name}: {differs.size} values differ, first at flat index {differs[0]}, "
            f"max |diff| {np.max(np.abs(value - pinned)):.3g}"
        )
