"""NMPC configuration: every tunable parameter with the paper's simulation defaults in one place.

Defaults are those of the paper's simulations (Sec. IV-A): tau = 0.1 s, N = 5,
v in [-1, 1] m/s, omega in [-pi/4, pi/4] rad/s, W_xi = diag(10, 15, 0.7),
W_u = diag(1, 0.1), W_v = I, W1 = 70, W2 = 10, alpha = 0.3, robot radius 0.25 m.
The paper gives no single gamma; 0.1 is the value its point-stabilisation figure uses for CBF.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Literal

import numpy as np

SafetyConstraint = Literal["none", "bt", "cbf", "relax-cbf"]
#: Obstacle constraint variants, in the order the paper compares them (plus the unconstrained baseline).
SAFETY_CONSTRAINTS: tuple[SafetyConstraint, ...] = ("none", "bt", "cbf", "relax-cbf")

SolverBackend = Literal["fatrop", "ipopt", "opti"]
#: NLP solvers (controllers.backends): structured FATROP (default), reference IPOPT, naive Opti.
SOLVER_BACKENDS: tuple[SolverBackend, ...] = ("fatrop", "ipopt", "opti")

ObstaclePrediction = Literal["constant-velocity", "frozen"]
OBSTACLE_PREDICTIONS: tuple[ObstaclePrediction, ...] = ("constant-velocity", "frozen")

Matrix = tuple[tuple[float, ...], ...]


class ConfigError(ValueError):
    """An invalid configuration value; the message names the field and the allowed range."""


def _as_matrix(value: Sequence[float] | Sequence[Sequence[float]], size: int, name: str) -> Matrix:
    """Accept a diagonal (length `size`) or a full size x size matrix; return it as nested tuples."""
    arr = np.asarray(value, dtype=float)
    if arr.shape == (size,):
        arr = np.diag(arr)
    if arr.shape != (size, size):
        raise ConfigError(
            f"{name}: expected {size} diagonal entries or a {size}x{size} matrix, got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: entries must be finite")
    if not np.allclose(arr, arr.T):
        raise ConfigError(f"{name}: must be symmetric positive definite, got a non-symmetric matrix")
    if np.linalg.eigvalsh(arr).min() <= 0.0:
        raise ConfigError(
            f"{name}: must be positive definite (all eigenvalues > 0), "
            f"smallest eigenvalue is {np.linalg.eigvalsh(arr).min():g}"
        )
    return tuple(tuple(float(v) for v in row) for row in arr)


@dataclass(frozen=True)
class SolverOptions:
    """Which NLP solver and its settings; a tight constraint tolerance so that plans satisfy
    their constraints to 1e-6 (IPOPT 1e-8; FATROP's solutions are checked to 1e-6)."""

    backend: SolverBackend = "fatrop"  # ipopt: the reference, and FATROP's fallback
    max_iter: int = 200
    tol: float = 1e-6  # IPOPT's overall (scaled) optimality tolerance
    acceptable_tol: float = 1e-6
    constr_viol_tol: float = 1e-8
    max_wall_time_s: float = 1.0  # a solve taking longer than this is a failure (fallback)

    def __post_init__(self) -> None:
        if self.backend not in SOLVER_BACKENDS:
            raise ConfigError(f"solver.backend: must be one of {SOLVER_BACKENDS}, got {self.backend!r}")
        if self.max_iter < 1:
            raise ConfigError(f"solver.max_iter: must be >= 1, got {self.max_iter}")
        for name in ("tol", "acceptable_tol", "constr_viol_tol", "max_wall_time_s"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ConfigError(f"solver.{name}: must be > 0 and finite, got {value}")


@dataclass(frozen=True)
class NMPCConfig:
    """Parameters of the NMPC-CLF OCP (paper Sec. III); weights are given as diagonals or matrices."""

    tau_s: float = 0.1  # sampling time (s)
    horizon: int = 5  # prediction steps N
    v_min_mps: float = -1.0  # linear velocity lower bound (m/s)
    v_max_mps: float = 1.0  # linear velocity upper bound (m/s)
    omega_max_radps: float = math.pi / 4  # |omega| bound (rad/s)
    state_weight: Matrix = ((10.0, 0, 0), (0, 15.0, 0), (0, 0, 0.7))  # W_xi on [x, y, theta]
    input_weight: Matrix = ((1.0, 0), (0, 0.1))  # W_u on [v, omega]
    clf_weight: Matrix = ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0))  # W_v of V = e^T W_v e
    clf_slack_weight: float = 70.0  # W1, cost W1 * s_v^2
    decay_slack_weight: float = 10.0  # W2, cost W2 * (s_h - 1)^2
    alpha: float = 0.3  # CLF decay rate in [0, 1]
    gamma: float = 0.1  # CBF decay rate in [0, 1]
    safety: SafetyConstraint = "cbf"
    robot_radius_m: float = 0.25  # radius of the robot's enclosing circle (m)
    obstacle_slots: int = 1  # obstacles the NLP is built for; more are reduced to the nearest
    obstacle_prediction: ObstaclePrediction = "constant-velocity"
    solver: SolverOptions = field(default_factory=SolverOptions)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "state_weight", _as_matrix(self.state_weight, 3, "state_weight"))
        set_(self, "input_weight", _as_matrix(self.input_weight, 2, "input_weight"))
        set_(self, "clf_weight", _as_matrix(self.clf_weight, 3, "clf_weight"))
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int | np.integer):
            raise ConfigError(f"horizon: must be an integer >= 1, got {self.horizon!r}")
        if self.horizon < 1:
            raise ConfigError(f"horizon: must be >= 1, got {self.horizon}")
        if not (self.tau_s > 0 and math.isfinite(self.tau_s)):
            raise ConfigError(f"tau_s: must be > 0 s and finite, got {self.tau_s}")
        if not (self.v_min_mps <= 0.0 < self.v_max_mps):
            raise ConfigError(
                f"v_min_mps/v_max_mps: need v_min_mps <= 0 < v_max_mps, "
                f"got [{self.v_min_mps}, {self.v_max_mps}]"
            )
        if not (self.omega_max_radps > 0 and math.isfinite(self.omega_max_radps)):
            raise ConfigError(f"omega_max_radps: must be > 0 rad/s, got {self.omega_max_radps}")
        for name in ("alpha", "gamma"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ConfigError(f"{name}: must be in [0, 1], got {value}")
        for name in ("clf_slack_weight", "decay_slack_weight"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ConfigError(f"{name}: must be > 0 and finite, got {value}")
        if not (self.robot_radius_m >= 0 and math.isfinite(self.robot_radius_m)):
            raise ConfigError(f"robot_radius_m: must be >= 0 m, got {self.robot_radius_m}")
        if self.obstacle_slots < 0:
            raise ConfigError(f"obstacle_slots: must be >= 0, got {self.obstacle_slots}")
        if self.safety not in SAFETY_CONSTRAINTS:
            raise ConfigError(f"safety: must be one of {SAFETY_CONSTRAINTS}, got {self.safety!r}")
        if self.obstacle_prediction not in OBSTACLE_PREDICTIONS:
            raise ConfigError(
                f"obstacle_prediction: must be one of {OBSTACLE_PREDICTIONS}, "
                f"got {self.obstacle_prediction!r}"
            )

    @property
    def uses_decay_slack(self) -> bool:
        """True when s_h is a decision variable (Relax-CBF); BT and CBF fix s_h = 1."""
        return self.safety == "relax-cbf"

    def with_(self, **changes: object) -> NMPCConfig:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def as_dict(self) -> dict[str, object]:
        """Plain-Python view for logs and summaries."""
        out: dict[str, object] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, SolverOptions):
                value = {g.name: getattr(value, g.name) for g in fields(value)}
            out[f.name] = value
        return out


#: The paper's Husky experiment parameters (Sec. IV-C): tau = 0.2 s, N = 5 (7 for tracking).
HUSKY_EXPERIMENT = dict(
    tau_s=0.2,
    horizon=5,
    state_weight=(15.0, 15.0, 0.1),
    input_weight=(0.01, 0.01),
    clf_weight=(1.0, 1.0, 1.0),
    clf_slack_weight=100.0,
    decay_slack_weight=10.0,
    alpha=0.2,
)
