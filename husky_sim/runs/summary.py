"""The typed record of one run, as summary.json holds it: which controller ran with which settings
(`RunSettings`) and what the episode measured (husky_sim.sim.metrics.EpisodeMetrics for a PyBullet
run, `KinematicMetrics` for the controller's own unicycle loop). `as_dict` is the file's flat layout;
husky_sim.runs.run_folder writes and reads it."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.sim.metrics import EpisodeMetrics

Model = Literal["physics", "kinematic"]


@dataclass(frozen=True)
class RunSettings:
    """Which controller ran on which scenario, with which settings (units in the names)."""

    scenario: str
    controller: str
    horizon: int  # prediction steps N
    gamma: float  # CBF decay rate
    seed: int  # sensor noise and random obstacle field
    model: Model
    tau_s: float
    prediction_time_s: float  # N * tau
    v_min_mps: float
    v_max_mps: float
    omega_max_radps: float  # the bound the controller commands within
    solver: str = "fatrop"  # the NLP backend it solved with (controllers.config.SOLVER_BACKENDS)
    robot: str = DEFAULT_ROBOT  # the robot's folder under assets/ (husky_sim.sim.robot_description)


@dataclass(frozen=True)
class KinematicMetrics:
    """Headline figures of a kinematic run (the subset of EpisodeMetrics that a unicycle without a
    drive has), and its per-control-step series for figures."""

    outcome: str
    collided: bool
    converged: bool
    min_clearance_m: float | None  # None without obstacles
    final_position_error_m: float
    tracking_rmse_m: float | None
    tracking_rmse_reachable_m: float | None
    reference_blocked_s: float | None
    rejoin_time_max_s: float | None
    time_to_goal_s: float | None
    reversals: int
    reverse_steps: int
    max_abs_v_mps: float  # commanded (the unicycle follows its command exactly)
    max_abs_omega_radps: float
    safety_active_steps: int
    fallbacks: int
    solve_ms_median: float  # over the steps that ran their solver (metrics.solver_times)
    repeated_steps: int  # steps that ran no solver, their problems answered before
    robot_radius_m: float  # the controller's circle, the body this model's clearance is measured on
    steps: int
    t_s: list[float]
    x_m: list[float]
    y_m: list[float]
    ref_x_m: list[float]
    ref_y_m: list[float]
    v_cmd_mps: list[float]
    omega_cmd_radps: list[float]

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class RunSummary:
    """One run: its settings and its metrics. `as_dict()` is summary.json's record (settings first)."""

    settings: RunSettings
    metrics: EpisodeMetrics | KinematicMetrics

    def as_dict(self) -> dict[str, object]:
        return {**asdict(self.settings), **self.metrics.as_dict()}
