"""`husky-sim bench-divergence` on real PyBullet loops with both solvers (shortened scenarios)."""

import numpy as np
import pytest

from husky_sim.bench.divergence import PART_TOL, trace_divergence
from husky_sim.cli import main
from husky_sim.runs.scenario import load_scenario

pytestmark = pytest.mark.physics


def test_without_obstacles_the_two_solvers_drive_the_same_loop() -> None:
    sc = load_scenario("husky_point_stabilisation").model_copy(update={"obstacles": [], "duration_s": 2.0})
    d = trace_divergence(sc.with_overrides(horizon=5), "cbf")
    assert d.part_step is None and d.solver_fallbacks == 0, d.report()
    assert "commands never part" in d.report()


def test_a_parting_step_is_reported_with_both_answers_and_the_converged_one() -> None:
    sc = load_scenario("husky_point_stabilisation").model_copy(update={"duration_s": 3.0})
    d = trace_divergence(sc.with_overrides(horizon=7), "bt")
    assert set(d.outcomes) == {"ipopt", "fatrop"}
    if d.part_step is None:  # the loops may agree on another CPU: then nothing more to check
        return
    assert d.commands is not None and d.converged is not None and d.objectives is not None
    ipopt, fatrop = np.array(d.commands["ipopt"]), np.array(d.commands["fatrop"])
    assert np.max(np.abs(ipopt - fatrop)) > PART_TOL
    assert np.all(np.isfinite(d.converged)) and np.isfinite(d.objectives["converged"])
    assert f"step {d.part_step}" in d.report()


def test_bad_input_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench-divergence", "narrow_gap", "--controller", "husky-cbf"]) == 2
    assert main(["bench-divergence", "narrow_gap", "--horizon", "0"]) == 2
    assert "error:" in capsys.readouterr().err
