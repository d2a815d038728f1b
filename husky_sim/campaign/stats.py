"""What a campaign counts: each run's class (reached, or the way it failed) and each failure
rate's exact one-sided 95 % upper confidence bound (Clopper-Pearson, scipy.stats.binomtest)."""

from __future__ import annotations

from collections.abc import Mapping

from scipy.stats import binomtest

#: The confidence of every bound a campaign reports.
CONFIDENCE = 0.95

#: Each run's class, in the order reports list them, with what it means.
CLASSES = {
    "reached": "reached the goal (set-point) or met the tracking criterion (tracking)",
    "collision_at_fault": "collided while moving (speed above the at-fault threshold at first contact)",
    "hit_standing": "collided while standing still: hit by a mover",
    "stuck": "deadlocked away from the goal (the run's stuck rule)",
    "timeout": "did not reach the goal in the layout's duration, without collision or deadlock",
    "tracking_lost": "tracked to the end without collision but missed the tracking criterion",
    "error": "the run crashed; nothing was measured",
}
FAILURES = tuple(c for c in CLASSES if c != "reached")


def run_class(row: Mapping[str, object]) -> str:
    """The class of one run from its summary fields (outcome, collided, collision_at_fault,
    converged). A collision whose class is unknown counts as at fault."""
    outcome = row.get("outcome")
    if outcome == "error":
        return "error"
    if _true(row.get("collided")) or outcome == "collided":
        return (
            "hit_standing"
            if row.get("collision_at_fault") in (False, "False", "false")
            else "collision_at_fault"
        )
    if outcome == "reached":
        return "reached"
    if outcome == "tracking":
        return "reached" if _true(row.get("converged")) else "tracking_lost"
    if outcome in ("stuck", "timeout"):
        return str(outcome)
    return "error"


def _true(value: object) -> bool:
    return value is True or value in ("True", "true", "1", 1)


def upper_bound(failures: int, runs: int) -> float:
    """The exact one-sided upper confidence bound (CONFIDENCE) on a rate seen as failures/runs."""
    if runs == 0:
        return 1.0
    return float(binomtest(failures, runs, alternative="less").proportion_ci(CONFIDENCE, "exact").high)


def rate_text(failures: int, runs: int) -> str:
    """`k/n (p %, <= u %)`: the count, the rate and its upper bound."""
    if runs == 0:
        return "0/0"
    return f"{failures}/{runs} ({100 * failures / runs:.0f} %, <= {100 * upper_bound(failures, runs):.0f} %)"
