"""The paper-claims report end to end (every run it needs, kinematic and in PyBullet, and the row
for our husky-cbf, PyBullet only): its verdicts must stay the ones measured and published in
docs/paper_claims.md. A change in any verdict, in either direction, fails here until the document
is regenerated (`husky-sim paper`) and the reason is written down."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from husky_sim.study.claims import (
    NOT_APPLICABLE,
    OURS,
    PARTLY,
    REPRODUCED,
    ClaimResult,
    Runs,
    claim_ours_prediction_time,
    claims_markdown,
    required_cells,
    run_paper_report,
)
from husky_sim.study.suite import Cell

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)

# (claim, kinematic verdict, PyBullet verdict), as measured on 2026-12-03 on the calibrated plant (default
# ground wet_grass); on the uncalibrated plant (2026-11-23) two PyBullet verdicts differed, marked below.
EXPECTED = [
    (
        "Point stabilisation, N >= 12: BT and CBF (and Relax-CBF) reach the goal safely",
        "reproduced",
        "not reproduced",
    ),
    (
        "Point stabilisation, N = 5: CBF reaches the goal while BT stops, reverses or sticks",
        "not reproduced",
        "not reproduced",
    ),
    (
        "Point stabilisation, N = 5, gamma = 0.05: plain CBF fails, Relax-CBF still reaches the goal",
        "not reproduced",
        "not reproduced",
    ),
    # partly on the uncalibrated plant
    (
        "paper_dynamic_tracking, N = 12: BT and Relax-CBF (gamma = 0.2) track safely",
        "reproduced",
        "reproduced",
    ),
    (
        "paper_dynamic_tracking, N = 5: Relax-CBF (gamma = 0.12) deviates earlier and is smoother than BT",
        "not reproduced",
        "not reproduced",
    ),
    (
        "paper_dynamic_tracking, N = 5, gamma = 0.03: plain CBF fails to track, Relax-CBF tracks",
        "partly",
        "not reproduced",
    ),
    # kinematic: not reproduced before the tracking definition excused the leave_s before a blockage
    (
        "paper_dynamic_tracking_crossing, N = 12: BT and Relax-CBF (gamma = 0.2) track safely",
        "reproduced",
        "not reproduced",
    ),
    (
        "paper_dynamic_tracking_crossing, N = 5: Relax-CBF (gamma = 0.12) deviates earlier and is smoother "
        "than BT",
        "partly",
        "not reproduced",
    ),
    (
        "paper_dynamic_tracking_crossing, N = 5, gamma = 0.03: plain CBF fails to track, Relax-CBF tracks",
        "not reproduced",
        "not reproduced",
    ),
    (
        "Control signals stay within their limits (every run of the paper's controllers in this report)",
        "reproduced",
        "reproduced",
    ),
    (
        "Shortest safe and converging N tau, simulation (point stabilisation, tau = 0.1 s)",
        "not reproduced",
        "not reproduced",
    ),
    (
        "Shortest safe and converging N tau, Husky problems (point + circle, tau = 0.2 s)",
        "not reproduced",
        "not reproduced",
    ),
    # ours, not the paper's: husky-cbf runs in PyBullet only; 0.3 s and 0.6 s (reproduced), on the
    # uncalibrated plant and on the calibrated one since husky-cbf plans over the drive's dead time
    # (0.7 s on the simulation problem without it: partly)
    (
        "Ours: husky-cbf, shortest safe and converging N tau in PyBullet on the paper's problems (point "
        "stabilisation, tau = 0.1 s; Husky point + circle, tau = 0.2 s) is at most the paper's Relax-CBF "
        "0.5 s and 1.4 s",
        "not applicable",
        "reproduced",
    ),
]


#: Claims whose verdict rests on a knife-edge mover cell, with the verdicts measured otherwise (on
#: another CPU, or after a change of the solver's answers within its tolerance). Either the published
#: or this verdict passes; any other fails. Measured on the calibrated plant.
MEASURED_OTHERWISE: dict[str, tuple[str, str]] = {
    # AMD EPYC, 2026-12-04 (the same at 7b09eb3 and d4bb220): Relax-CBF N = 12, gamma = 0.2 collides
    # with the mover (clearance -0.017 m) where it tracks on the Intel Xeon the table was measured on
    "paper_dynamic_tracking, N = 12: BT and Relax-CBF (gamma = 0.2) track safely": ("reproduced", "partly"),
}


@pytest.mark.slow
def test_paper_report_verdicts_match_the_published_ones(tmp_path: Path) -> None:
    results = run_paper_report(tmp_path, jobs=2, progress=False)
    measured = [(r.claim, r.kinematic.verdict, r.physics.verdict) for r in results]
    assert [c for c, _, _ in measured] == [c for c, _, _ in EXPECTED]
    for (claim, kinematic, physics), (_, *expected) in zip(measured, EXPECTED, strict=True):
        allowed = [tuple(expected), *([MEASURED_OTHERWISE[claim]] if claim in MEASURED_OTHERWISE else [])]
        assert (kinematic, physics) in allowed, f"{claim}: {kinematic} / {physics}, measured: {allowed}"
    published = (Path(__file__).parents[2] / "docs" / "paper_claims.md").read_text().splitlines()
    for claim, kinematic, physics in EXPECTED:
        row = next(line for line in published if line.startswith(f"| {claim} |"))
        cells = [c.strip() for c in row.split("|")]
        assert (cells[3], cells[5]) == (f"**{kinematic}**", f"**{physics}**"), claim
    written = json.loads((tmp_path / "claims.json").read_text())
    assert [w["claim"] for w in written] == [c for c, _, _ in EXPECTED]
    assert "| **" in (tmp_path / "claims.md").read_text()


def _ours_runs(succeeds: Callable[[Cell], bool]) -> Runs:
    """Runs of every husky-cbf cell of the report, none simulated: each succeeds as `succeeds` says."""
    cells = [c for c in required_cells("physics") if c.controller == OURS]
    rows = [
        {
            "scenario": c.scenario,
            "controller": c.controller,
            "horizon": c.horizon,
            "tau_s": 0.1 if c.scenario.startswith("paper_") else 0.2,
            "outcome": "reached" if succeeds(c) else "stuck",
            "converged": succeeds(c),
            "collided": False,
        }
        for c in cells
    ]
    return Runs(cells, rows, Path("."))


def test_ours_row_is_judged_from_the_runs_and_not_applicable_kinematically() -> None:
    assert not [c for c in required_cells("kinematic") if c.controller == OURS]
    # N tau at most the paper's on both problems: 0.5 s (N = 5, tau 0.1) and 1.4 s (N = 7, tau 0.2)
    both = claim_ours_prediction_time(
        _ours_runs(lambda c: c.horizon >= (5 if c.scenario.startswith("paper_") else 7)), "physics"
    )
    assert both.verdict == REPRODUCED, both.evidence
    assert "0.5 s" in both.evidence and "1.4 s" in both.evidence
    # the Husky problems need N = 8 (1.6 s): only one problem at most the paper's
    one = claim_ours_prediction_time(
        _ours_runs(lambda c: c.horizon >= (5 if c.scenario.startswith("paper_") else 8)), "physics"
    )
    assert one.verdict == PARTLY, one.evidence
    assert "N=7 husky_point_stabilisation stuck" in one.evidence
    kinematic = claim_ours_prediction_time(_ours_runs(lambda c: True), "kinematic")
    assert kinematic.verdict == NOT_APPLICABLE
    totals = claims_markdown([ClaimResult("c", "p", kinematic, both)]).splitlines()[-1]
    assert totals == (
        "Totals: kinematic: 0 reproduced, 0 partly, 0 not reproduced, 1 not applicable; "
        "physics: 1 reproduced, 0 partly, 0 not reproduced"
    )
    every = claim_ours_prediction_time(_ours_runs(lambda c: True), "physics")
    assert (
        "husky-cbf 0.3 s against the paper's Relax-CBF 0.5 s (N = 3, the shortest scanned" in every.evidence
    )
