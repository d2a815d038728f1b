"""Alternative initial guesses after a failed solve, shared by every controller.

IPOPT can report a solvable problem infeasible from a poor starting point: the slalom at N = 12
braked to its end on `Infeasible_Problem_Detected` although v = -1 m/s, omega = +0.785 rad/s
satisfies every constraint and the same NLP solves from that guess. So a failed solve is retried
from these command sequences, in this order, before any fallback brakes; the one that succeeded is
counted (ControlResult.recovered_by).
"""

from __future__ import annotations

import numpy as np

#: Names of the retry guesses, in the order they are tried.
RECOVERY_GUESSES = ("brake", "previous-plan", "reverse", "straight")


def recovery_commands(
    state_xy_theta: np.ndarray,
    target_xy_theta: np.ndarray,
    previous: np.ndarray | None,
    horizon: int,
    tau_s: float,
    v_bounds_mps: tuple[float, float],
    omega_max_radps: float,
) -> list[tuple[str, np.ndarray]]:
    """(name, (N, 2) [v (m/s), omega (rad/s)] sequence) per retry guess; `previous` is the last
    solved plan's commands shifted to now (None when there is none)."""
    v_min, v_max = v_bounds_mps
    zeros = np.zeros((horizon, 2))
    out: list[tuple[str, np.ndarray]] = [("brake", zeros)]
    if previous is not None:
        out.append(("previous-plan", np.asarray(previous, dtype=float)))
    out.append(("reverse", np.tile([0.5 * v_min, 0.0], (horizon, 1))))
    delta = np.asarray(target_xy_theta[:2], dtype=float) - np.asarray(state_xy_theta[:2], dtype=float)
    heading = float(np.arctan2(delta[1], delta[0]))
    turn = float(np.angle(np.exp(1j * (heading - float(state_xy_theta[2])))))
    span = horizon * tau_s
    v = float(np.clip(np.hypot(*delta) / span, v_min, v_max))
    omega = float(np.clip(turn / span, -omega_max_radps, omega_max_radps))
    out.append(("straight", np.tile([v, omega], (horizon, 1))))
    return out
