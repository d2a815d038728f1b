"""husky-cbf's safety filter in the closed loop: real PyBullet, real solver, a generated layout.

The layout is a generated crossing (crossing_walkers, seed 1, layout 4, N = 5) in which husky-cbf
without its filter drives into a walker. The test is that the filter turns a contact while moving
into none while moving, and that the summary counts its interventions; if the controller or the
family changes so that the unfiltered run no longer collides, pick another layout of the kind."""

from __future__ import annotations

import pytest
import yaml

from husky_sim.families.generate import draw_layout
from husky_sim.runs.run import run_scenario
from husky_sim.runs.scenario import scenario_from_data

pytestmark = pytest.mark.physics


def _run(safety_filter: bool) -> dict[str, object]:
    data = yaml.safe_load(draw_layout("crossing_walkers", 1, 4).text)
    data["controller"] = {**data["controller"], "husky_cbf": {"safety_filter": safety_filter}}
    return run_scenario(scenario_from_data(data), "husky-cbf", horizon=5).as_dict()


def test_the_filter_brakes_where_the_nmpc_would_drive_into_a_walker() -> None:
    without = _run(False)
    assert without["collision_at_fault"] is True and without["filter_interventions"] == 0
    with_filter = _run(True)
    assert with_filter["collision_at_fault"] is not True
    assert with_filter["filter_interventions"] > 0
