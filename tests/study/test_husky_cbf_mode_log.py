"""husky-cbf logs which behaviour its plan tracked, step by step, and its summary counts the
switches: real PyBullet, real solver, a generated crossing (crossing_walkers, seed 1, layout 4,
N = 5) in which a walker crosses the robot's way, so that it yields and then goes on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from controllers.husky_cbf.arbiter import Mode
from husky_sim.families.generate import draw_layout
from husky_sim.runs.run import run_scenario
from husky_sim.runs.run_folder import read_log
from husky_sim.runs.scenario import scenario_from_data

pytestmark = pytest.mark.physics


def test_the_log_names_each_steps_behaviour_and_the_summary_counts_its_changes(tmp_path: Path) -> None:
    data = yaml.safe_load(draw_layout("crossing_walkers", 1, 4).text)
    summary = run_scenario(scenario_from_data(data), "husky-cbf", horizon=5, out_dir=tmp_path).as_dict()
    modes = read_log(tmp_path)["mode"]
    assert set(modes) <= {m.value for m in Mode}
    assert Mode.YIELD.value in modes and Mode.APPROACH.value in modes  # it yields, then goes on
    assert summary["mode_changes"] == int(np.sum(modes[1:] != modes[:-1])) > 0
