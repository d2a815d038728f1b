"""Robustness sweep: one scenario re-run over seeded perturbations of what differs on a real Husky.

Each sample draws, from `PerturbationRanges` with ``numpy.random.default_rng(seed)``, the ground
friction, payload, control latency, pose and obstacle-position noise, an obstacle-velocity
estimation error and a wheel-torque derating, and writes them into a copy of the scenario
(`apply_perturbation`, validated again by the scenario schema). The perturbed scenario is a
plain scenario file: saved as YAML it reproduces the sample with ``husky-sim run``.

The lidar's visibility model (husky_sim.sim.sensing: range, occlusion) is perturbed only when
asked (``--sensing-range-m LOW HIGH``, ``--occlusion``): its default ranges draw nothing, so a
seeded check draws the same samples, and reaches the same verdicts, as without it.

Obstacle speed error: in the simulator the controller is told each obstacle's *true* velocity, so
changing how fast an obstacle really moves would only make a different scenario the controller
still knows exactly. What a real robot gets wrong is its *estimate* of that velocity. The sweep
therefore scales the velocity the controller is told (``sensing.obstacle_velocity_scale``, 0.8
to 1.2 by default) while the obstacles keep their true motion.

Execution backends, both through husky_sim.runs.parallel.parallel_map as the suite's cells are
(the same picklable `run_sample` for both, so results are identical):

- ``local`` (default): husky_sim.runs.parallel.process_map on this machine's cores
  (``spawn`` start method: CasADi/IPOPT and PyBullet are not fork-safe once threads exist).
  Needs nothing beyond the project's dependencies.
- ``dask``: husky_sim.runs.parallel.dask_map, ``distributed.Client.map`` on a Dask cluster
  (``--scheduler ADDRESS``, or an in-process ``distributed.LocalCluster``), for thousands of
  samples. Dask rather than Ray: Dask/distributed are pure-Python wheels with a small install, a
  LocalCluster starts in-process in CI in about 1-2 s, and the same ``Client.map`` code runs
  unchanged on any cluster (SSH, SLURM, Kubernetes); Ray is a large binary wheel with a heavier
  runtime (GCS, raylet, object store). Dask is an optional extra (``pip install
  husky-nav-sim[cluster]``) imported only there, lazily. Workers of a remote cluster need this
  package installed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from husky_sim.realcheck.steerability import steerability
from husky_sim.runs.parallel import Backend, parallel_map
from husky_sim.runs.scenario import MAX_SENSING_RANGE_M, Scenario, scenario_from_data
from husky_sim.sim.robot_description import RobotDescription
from husky_sim.sim.tyre import stiffness_ratio_for_yaw_ratio

#: Per-sample result keys that are wall-clock measurements (excluded from determinism checks).
WALL_CLOCK_KEYS = ("solve_ms_median", "solve_ms_p95", "solve_ms_max", "wall_time_s")
#: A sample's result: these fields of its run summary (run_sample; None where it crashed)
SAMPLE_KEYS = (
    "outcome",
    "collided",
    "converged",
    "min_clearance_m",
    "final_position_error_m",
    "tracking_rmse_m",
    "tracking_rmse_reachable_m",
    "rejoin_time_max_s",
    "time_to_goal_s",
    "fallbacks",
    "steps",
    *WALL_CLOCK_KEYS,
)


@dataclass(frozen=True)
class PerturbationRanges:
    """Uniform sampling ranges (low, high) of the real-world differences; all defaults live here.

    Absolute values replace the scenario's own (friction, payload, latency, noise, yaw ratio: the
    last on a calibrated ground only, the uncalibrated one has no tyre stiffness); the two
    factors are relative to the scenario's nominal value (torque limit, reported obstacle speed).
    """

    ground_friction: tuple[float, float] = (0.4, 1.0)  # ground-plane friction coefficient
    #: kg on the top plate; None: 0 to the robot's all-terrain payload (specs.yaml; the Husky's
    #: maker rates it for "turning in place in high-friction conditions", the maximum payload only
    #: for "relatively flat terrain with wide turns"); a heavier robot is checked with
    #: `--payload-kg LOW HIGH` around what it carries, at most the robot's maximum payload
    payload_kg: tuple[float, float] | None = None
    latency_steps: tuple[int, int] = (0, 2)  # control steps, inclusive integer range
    pose_xy_std_m: tuple[float, float] = (0.0, 0.05)  # localisation position noise std, m
    pose_yaw_std_rad: tuple[float, float] = (0.0, 0.03)  # localisation heading noise std, rad
    obstacle_xy_std_m: tuple[float, float] = (0.0, 0.05)  # obstacle-detection position noise std, m
    obstacle_velocity_scale: tuple[float, float] = (0.8, 1.2)  # reported / true obstacle speed
    torque_scale: tuple[float, float] = (0.7, 1.0)  # motor current (torque) limit / nominal
    #: the plant's steady yaw ratio (measured / wheel-implied yaw rate): the real runs we know span
    #: 0.43-0.54 (husky_sim.calibration); set through the tyres' lateral stiffness
    yaw_ratio: tuple[float, float] = (0.43, 0.54)
    #: the lidar's range (m, sensing.range_m) in (0, MAX_SENSING_RANGE_M]; (inf, inf): not
    #: perturbed (each sample keeps the scenario's range)
    sensing_range_m: tuple[float, float] = (math.inf, math.inf)
    #: occlusion by static obstacles (sensing.occlusion), an inclusive integer range of 0 (the
    #: scenario's own setting) and 1 (on): (0, 0) never forces it on, (1, 1) always, (0, 1) draws
    occlusion: tuple[int, int] = (0, 0)

    def __post_init__(self) -> None:
        for f in fields(self):
            if getattr(self, f.name) is None or f.name in SENSING_MODEL_FIELDS:
                continue
            low, high = getattr(self, f.name)
            if not (np.isfinite(low) and np.isfinite(high) and 0 <= low <= high):
                raise ValueError(f"perturbation range {f.name}: need 0 <= low <= high, got ({low}, {high})")
        low, high = self.sensing_range_m
        if (low, high) != (math.inf, math.inf) and not 0 < low <= high <= MAX_SENSING_RANGE_M:
            raise ValueError(
                f"perturbation range sensing_range_m: need 0 < low <= high <= {MAX_SENSING_RANGE_M:g} m "
                f"(or inf, inf: not perturbed), got ({low}, {high})"
            )
        low, high = self.occlusion
        if not (low in (0, 1) and high in (0, 1) and low <= high):
            raise ValueError(f"perturbation range occlusion: need 0 <= low <= high <= 1, got ({low}, {high})")

    def for_robot(self, robot: RobotDescription) -> PerturbationRanges:
        """These ranges with the payload decided for `robot`: 0 to its all-terrain payload unless
        given; a payload above its maximum is a one-line ValueError."""
        sheet = robot.specs.spec_sheet
        low, high = self.payload_kg or (0.0, sheet.all_terrain_payload_kg)
        if high > sheet.max_payload_kg:
            raise ValueError(
                f"--payload-kg: at most {sheet.max_payload_kg:g} kg on a {robot.title} "
                f"(its maximum payload), got {high:g}"
            )
        return replace(self, payload_kg=(low, high))


@dataclass(frozen=True)
class Perturbation:
    """One sample's real-world values (units as in PerturbationRanges) and its episode seed."""

    index: int
    episode_seed: int  # seeds the sensing noise of the episode (scenario.seed)
    ground_friction: float
    payload_kg: float
    latency_steps: int
    pose_xy_std_m: float
    pose_yaw_std_rad: float
    obstacle_xy_std_m: float
    obstacle_velocity_scale: float
    torque_scale: float
    yaw_ratio: float
    sensing_range_m: float | None = None  # None: the scenario's own range
    occlusion: bool = False  # True: occlusion on (False: the scenario's own setting)

    def as_dict(self) -> dict[str, float | int | bool | None]:
        return asdict(self)

    def describe(self) -> str:
        """One line with every perturbed value and its unit."""
        sensing = "" if self.sensing_range_m is None else f"sensing range {self.sensing_range_m:.1f} m, "
        sensing += "occlusion on, " if self.occlusion else ""
        return (
            f"friction {self.ground_friction:.2f}, payload {self.payload_kg:.1f} kg, "
            f"latency {self.latency_steps} steps, pose noise {self.pose_xy_std_m * 100:.1f} cm / "
            f"{np.degrees(self.pose_yaw_std_rad):.2f} deg, "
            f"obstacle noise {self.obstacle_xy_std_m * 100:.1f} cm, "
            f"obstacle speed x{self.obstacle_velocity_scale:.2f}, torque x{self.torque_scale:.2f}, "
            f"yaw ratio {self.yaw_ratio:.2f}, {sensing}"
            f"seed {self.episode_seed}"
        )


def sample_perturbations(ranges: PerturbationRanges, count: int, seed: int) -> list[Perturbation]:
    """`count` perturbations drawn in a fixed order from default_rng(seed): same inputs, same list.
    The sensing model's fields are drawn last, and only from a range of more than one value (a
    single value is taken as is), so its default ranges leave every other draw as it was."""
    if count < 1:
        raise ValueError(f"samples: must be >= 1, got {count}")
    if ranges.payload_kg is None:
        raise ValueError("perturbation ranges: decide the payload for a robot first (for_robot)")
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        episode_seed = int(rng.integers(0, 2**31 - 1))
        uniform = {
            name: float(rng.uniform(*getattr(ranges, name)))
            for name in (
                "ground_friction",
                "payload_kg",
                "pose_xy_std_m",
                "pose_yaw_std_rad",
                "obstacle_xy_std_m",
                "obstacle_velocity_scale",
                "torque_scale",
            )
        }
        low, high = ranges.latency_steps
        latency = int(rng.integers(int(low), int(high) + 1))
        uniform["yaw_ratio"] = float(rng.uniform(*ranges.yaw_ratio))  # drawn last: the others as before
        sensing = _draw_sensing(ranges, rng)  # after yaw_ratio, and nothing at its defaults
        out.append(
            Perturbation(index=i, episode_seed=episode_seed, latency_steps=latency, **uniform, **sensing)
        )
    return out


#: The sensing model's fields of PerturbationRanges (their own defaults mean "not perturbed").
SENSING_MODEL_FIELDS = ("sensing_range_m", "occlusion")


def _draw_sensing(ranges: PerturbationRanges, rng: np.random.Generator) -> dict[str, float | bool | None]:
    """One sample's sensing range (m; None: not perturbed) and occlusion, drawn only from ranges
    of more than one value."""
    low, high = ranges.sensing_range_m
    range_m = None if math.isinf(low) else float(low if low == high else rng.uniform(low, high))
    low, high = ranges.occlusion
    occlusion = bool(low if low == high else rng.integers(int(low), int(high) + 1))
    return {"sensing_range_m": range_m, "occlusion": occlusion}


def nominal_current_a(scenario: Scenario) -> float:
    """The scenario's motor current limit (A): its drive override or the MotorConfig default."""
    return scenario.drive_config().motor.current_limit_a


def apply_perturbation(scenario: Scenario, p: Perturbation) -> Scenario:
    """A validated copy of `scenario` with the sample's values written into its fields."""
    data = scenario.model_dump()
    data["name"] = f"{scenario.name}__check_sample_{p.index}"
    data["description"] = f"husky-sim check sample {p.index} of {scenario.name}: {p.describe()}"
    data["seed"] = p.episode_seed
    data["friction"]["ground"] = p.ground_friction
    data["robot"]["payload_kg"] = p.payload_kg
    data["drive"]["current_limit_a"] = nominal_current_a(scenario) * p.torque_scale
    ground = scenario.ground_config()
    if ground.calibrated:  # the uncalibrated plant has no tyre stiffness to set
        rolling = ground.tyre.rolling_radius_scale
        data["friction"]["lateral_stiffness_ratio"] = stiffness_ratio_for_yaw_ratio(
            p.yaw_ratio, scenario.robot.description().geometry, rolling
        )
    data["sensing"].update(
        latency_steps=p.latency_steps,
        pose_xy_std_m=p.pose_xy_std_m,
        pose_yaw_std_rad=p.pose_yaw_std_rad,
        obstacle_xy_std_m=p.obstacle_xy_std_m,
        obstacle_velocity_scale=scenario.sensing.obstacle_velocity_scale * p.obstacle_velocity_scale,
    )
    if p.sensing_range_m is not None:
        data["sensing"]["range_m"] = p.sensing_range_m
    if p.occlusion:
        data["sensing"]["occlusion"] = True
    return scenario_from_data(data, f"check sample {p.index}")


@dataclass(frozen=True)
class SampleTask:
    """Everything one worker needs, as plain data (picklable, sent to any backend)."""

    index: int
    scenario: dict[str, Any]  # Scenario.model_dump(mode="json") of the perturbed scenario
    controller: str


def run_sample(task: SampleTask) -> dict[str, Any]:
    """Run one perturbed scenario in PyBullet; return its headline metrics and its robot's
    steerability (a short open-loop probe of the same plant; JSON-able)."""
    from husky_sim.runs.run import run_scenario  # imported in the worker

    scenario = scenario_from_data(task.scenario, f"check sample {task.index}")
    summary = run_scenario(scenario, task.controller).as_dict()  # horizon, gamma, seed: in the scenario
    out = {"index": task.index, **{k: summary[k] for k in SAMPLE_KEYS}}
    out["passed"] = bool(summary["converged"]) and not bool(summary["collided"])
    out["steerability"] = steerability(scenario)
    return out


def default_jobs() -> int:
    """Cores this process may use."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not Linux
        return max(os.cpu_count() or 1, 1)


def error_result(task: SampleTask, exc: BaseException) -> dict[str, Any]:
    """A sample that crashed: it fails the check and names the error."""
    return {
        "index": task.index,
        **dict.fromkeys(SAMPLE_KEYS),
        "outcome": "error",
        "error": f"{type(exc).__name__}: {str(exc)[:200]}",
        "collided": False,
        "converged": False,
        "steps": 0,
        "passed": False,
    }


def run_tasks(
    tasks: Sequence[SampleTask],
    backend: Backend = "local",
    jobs: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[dict]:
    """Per-sample results in task order, whichever backend ran them (husky_sim.runs.parallel; one
    process when jobs == 1); a sample whose worker crashed becomes an `error` result (failing, and
    saved for a rerun)."""
    jobs = default_jobs() if jobs is None else jobs
    finished = [0]

    def done(_i: int, _result: object) -> None:
        finished[0] += 1
        if progress:
            progress(finished[0])

    results = parallel_map(run_sample, tasks, jobs, done, backend, scheduler)
    return [
        error_result(t, r) if isinstance(r, BaseException) else r for t, r in zip(tasks, results, strict=True)
    ]
