"""A proof that one control step's OCP has no solution, from where the robot can get to.

The unicycle's RK4 step moves the robot by tau/6 (u(th) + 4 u(th + w tau/2) + u(th + w tau)) v,
with u(a) the unit vector at heading a: at most |v| tau, along a heading within w tau of the
step's start. So after k steps the heading is within k w_max tau of the measured one, and the
position lies in p + k H_k, H_k the convex hull of the two sectors (forward to v_max tau,
backward to |v_min| tau) of half-angle k w_max tau round the measured heading and its opposite.
Where even the farthest of those positions from an obstacle's predicted centre breaks a safety
row (BT: clearance >= 0; CBF: B(k) >= (1 - gamma)^k B(0); Relax-CBF: the same chain with s_h in
[0, 1]), no decision satisfies the OCP, and no solver or initial guess can find one.

A paper controller deadlocked against an obstacle (0.1 m inside its BT circle, with 0.1 m of
travel per step) or overrun by a mover poses such a problem on step after step; each was handed to
FATROP, IPOPT and up to four recovery guesses (up to ten solves, ~80 ms at N = 12), all failing.

Every row may be violated by ROW_TOL in the proof, at least 50 times more than an accepted solution:
FATROP's answers are checked to 1e-6, and IPOPT stops at an error of 1e-6 on its scaled problem,
which scales no row used here down by more than half (a barrier row's gradient, twice the distance,
reaches 200 only for a parked slot 100 m away; IPOPT scales rows whose gradient exceeds 100).
Relax-CBF is only judged while some barrier at the measured state is <= 0: the structured solver
loosens s_h <= 1 otherwise (controllers.ocp.redundant_bounds).
"""

from __future__ import annotations

import math

import numpy as np

from controllers.config import NMPCConfig
from controllers.ocp import OCPParameters

#: Each constraint row (dynamics, initial state, safety) may be violated by this much (m, rad, m^2)
#: in the proof, and bounds on s_h by this much.
ROW_TOL = 1e-4
#: (radial, angular) cells over the positions one control step can reach, for first_step_covered:
#: a cell is 3 mm by at most 2 mm at 1 m/s, tau = 0.1 s and pi/4 rad/s.
COVER_CELLS = (64, 8)


def farthest_reachable(
    state: np.ndarray, points: np.ndarray, steps: np.ndarray, config: NMPCConfig
) -> np.ndarray:
    """An upper bound (m) on the distance from `points` (M, 2) of any position the robot can reach
    from `state` [x m, y m, theta rad] in `steps` (M,) control steps, each row of the trajectory
    allowed ROW_TOL."""
    tau, w = config.tau_s, config.omega_max_radps
    k = steps.astype(float)
    offset = state[:2] - points
    here = np.hypot(offset[:, 0], offset[:, 1])
    away = np.arctan2(offset[:, 1], offset[:, 0])  # the heading that increases the distance
    half_angle = k * (w * tau + ROW_TOL)
    wide = half_angle >= math.pi / 2  # the sectors' hull is then a disc
    best = here
    for reach_mps, heading in ((config.v_max_mps, state[2]), (-config.v_min_mps, state[2] + math.pi)):
        if reach_mps <= 0:
            continue
        radius = k * reach_mps * tau
        turn = np.remainder(away - heading + math.pi, 2 * math.pi) - math.pi
        toward = heading + np.minimum(np.maximum(turn, -half_angle), half_angle)  # arc point nearest `away`
        arc = np.hypot(offset[:, 0] + radius * np.cos(toward), offset[:, 1] + radius * np.sin(toward))
        if wide.any():
            arc = np.where(wide, here + radius, arc)
        best = np.maximum(best, arc)
    return best + (k + 1) * math.sqrt(2.0) * ROW_TOL


def proven_infeasible(config: NMPCConfig, params: OCPParameters) -> str:
    """Why no decision can satisfy this step's safety rows (the first obstacle slot and step that
    prove it), or "" where reachability proves nothing."""
    safety = config.safety
    if safety == "none" or config.obstacle_slots == 0:
        return ""
    n = config.horizon
    steps = np.arange(1, n + 1)
    centres = np.asarray(params.obstacle_centres, dtype=float)  # (slots, N+1, 2)
    r_sum = config.robot_radius_m + np.asarray(params.obstacle_radii, dtype=float)  # (slots,)
    state = np.asarray(params.feedback, dtype=float)
    offset = state[:2] - centres
    distance = np.hypot(offset[..., 0], offset[..., 1])  # (slots, N+1) from the measured position
    needed = _least_distance(config, distance[:, 0], r_sum, steps)  # (slots, N)
    if needed is None:
        return ""
    # no reachable point is nearer the farthest one than the measured position: only a row the
    # measured position breaks can be out of reach
    slots, before = np.nonzero(distance[:, 1:] < needed)
    if slots.size == 0:
        return ""
    farthest = farthest_reachable(state, centres[slots, before + 1], before + 1, config)
    broken = np.flatnonzero(farthest < needed[slots, before])
    if broken.size:
        slot, k = slots[broken[0]], before[broken[0]] + 1
        return f"{safety} row of obstacle slot {slot} at step {k} out of reach"
    # the measured position is one of the positions one step reaches: where it keeps every
    # step-1 row, nothing is covered
    together = np.any(distance[:, 1] < needed[:, 0]) and first_step_covered(
        state, centres[:, 1], needed[:, 0], config
    )
    if together:
        return (
            f"{safety} rows of obstacle slots {', '.join(map(str, together))} at step 1 out of reach together"
        )
    return ""


def first_step_covered(
    state: np.ndarray, centres: np.ndarray, needed_m: np.ndarray, config: NMPCConfig
) -> list[int]:
    """The obstacle slots whose discs (centres (slots, 2) at step 1, radii needed_m) cover every
    position one control step can reach (a squeeze between obstacles that each alone could be
    escaped), or [] where some position may be free.

    One step is a single control: the robot moves by rho u(theta + phi), rho in [v_min tau, v_max tau]
    (0 included), |phi| <= w_max tau. The (rho, phi) box is cut into COVER_CELLS cells; a cell whose
    every point (its centre, plus the distance any of its points can lie from it) is nearer some
    obstacle's centre than that obstacle's rows allow is covered."""
    tau = config.tau_s
    low, high = min(config.v_min_mps, 0.0) * tau, max(config.v_max_mps, 0.0) * tau
    half_angle = config.omega_max_radps * tau + ROW_TOL
    radial, angular = COVER_CELLS
    rho = low + (np.arange(radial) + 0.5) * (high - low) / radial
    phi = -half_angle + (np.arange(angular) + 0.5) * 2.0 * half_angle / angular
    rho, phi = (a.ravel() for a in np.meshgrid(rho, phi, indexing="ij"))
    heading = state[2] + phi
    cells = state[:2] + np.column_stack([rho * np.cos(heading), rho * np.sin(heading)])
    # any point rho' u(theta + phi') of a cell lies within |rho' - rho| + |rho| |phi' - phi| of its
    # centre; x_0 and x_1 may each be ROW_TOL off per coordinate
    spread = (high - low) / (2 * radial) + np.abs(rho) * half_angle / angular + 2 * math.sqrt(2.0) * ROW_TOL
    offset = cells[:, None, :] - centres[None, :, :]
    inside = np.hypot(offset[..., 0], offset[..., 1]) + spread[:, None] < needed_m[None, :]  # (cells, slots)
    if not np.all(inside.any(axis=1)):
        return []
    return [int(i) for i in np.flatnonzero(inside.any(axis=0))]


def _least_distance(
    config: NMPCConfig, now_m: np.ndarray, r_sum_m: np.ndarray, steps: np.ndarray
) -> np.ndarray | None:
    """The least distance (m) from obstacle slot i's predicted centre at step k = 1..N that its
    safety rows allow (slots, N), given its distance now; None where the proof does not apply."""
    if config.safety == "bt":  # clearance(k) >= -ROW_TOL
        return np.broadcast_to((r_sum_m - ROW_TOL)[:, None], (len(r_sum_m), len(steps)))
    if config.safety == "relax-cbf" and np.min(now_m**2 - r_sum_m**2) > 0:
        return None  # every barrier positive: the structured solver lets s_h exceed 1
    # B(0) at the decision's x_0, within ROW_TOL of the measured state
    b0 = np.maximum(now_m - math.sqrt(2.0) * ROW_TOL, 0.0) ** 2 - r_sum_m**2
    decay = 1.0 - config.gamma
    if config.safety == "cbf":  # B(k) >= decay B(k-1) - ROW_TOL
        lowest = decay**steps * b0[:, None] - steps * ROW_TOL
    else:  # relax-cbf: B(k) >= s_h decay B(k-1) - ROW_TOL, weakest at s_h = 0 or at its bound
        lowest = np.empty((len(b0), len(steps)))
        level = b0
        for k in range(len(steps)):
            level = (1.0 + ROW_TOL) * decay * np.minimum(level, 0.0) - ROW_TOL
            lowest[:, k] = level
    # B = d^2 - r^2 >= lowest  <=>  d >= sqrt(lowest + r^2) (any d >= 0 where that is negative)
    return np.sqrt(np.maximum(lowest + r_sum_m[:, None] ** 2, 0.0))
