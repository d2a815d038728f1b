"""The registry of controllers: each is registered once, in its own package, as a
`ControllerEntry`: its name, how it is configured and built from what a scenario says
(`ControllerInputs`), the settings a scenario may give it, and what its plans promise
(`PlanProfile`, for a run's settings and the pre-trial audit). Every list of names, every
factory and every question about a controller in the simulator and the tools reads it here.

Built in: the paper's four (controllers.paper) and husky-cbf (controllers.husky_cbf.registration).
Another package registers its own under the entry-point group `husky_nav_sim.controllers` (each
value a ControllerEntry), so that worker processes find it too; `register` adds one in this
process only (a test's, or a notebook's).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

from controllers.config import NMPCConfig
from controllers.interface import Controller

#: The modules that register the built-in controllers, in the order names are listed.
BUILT_IN = ("controllers.paper", "controllers.husky_cbf.registration")
#: The entry-point group under which other packages register controllers.
ENTRY_POINT_GROUP = "husky_nav_sim.controllers"
#: What `run`, `check` and the audit test unless told: the paper's method.
DEFAULT = "relax-cbf"
#: What `serve` and `rehearse` drive a robot with unless told: the one the suite says yes to.
DEFAULT_ON_ROBOT = "husky-cbf"


@dataclass(frozen=True)
class RobotFacts:
    """What a controller may be told of the robot it drives (the simulator's robot description, or
    a real robot's), as plain numbers: drive limits, the identified yaw response, the body, and the
    localisation's reported noise."""

    max_linear_mps: float  # wheel drive's speed limit (m/s)
    max_angular_radps: float  # drive's yaw-rate command limit (rad/s)
    max_linear_accel_mps2: float  # (m/s^2)
    max_angular_accel_radps2: float  # (rad/s^2)
    yaw_gain: float  # body yaw rate / commanded yaw rate in steady state
    yaw_time_constant_s: float  # first-order lag of the body yaw rate (s)
    command_delay_s: float  # drive dead time before a command acts (s)
    half_separation_m: float  # half the drive's effective wheel separation (m)
    footprint_half_extents_m: tuple[float, float]  # body rectangle about the base origin (m)
    pose_xy_std_m: float = 0.0  # localisation's position noise per axis (m)
    pose_yaw_std_rad: float = 0.0  # localisation's heading noise (rad)
    sensing_latency_s: float = 0.0  # how old the reported pose and obstacles are when they arrive (s)
    sensor_fov_deg: float = 360.0  # the obstacle sensor's field of view, centred on the heading (deg)


@dataclass(frozen=True)
class ControllerInputs:
    """What a controller is built from: the scenario's NMPC settings (the paper's part, with the
    scenario's robot circle and obstacle slots), the robot, the scenario's obstacle count, and the
    settings the scenario gave this controller (`controller.<settings key>`, validated)."""

    nmpc: NMPCConfig
    robot: RobotFacts
    obstacle_count: int
    settings: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class BodyDiscs:
    """A body covered by discs along its length: their count and radius (m), the rectangle they
    cover (half extents, m) and the margin kept between each disc and an obstacle (m)."""

    count: int
    radius_m: float
    footprint_half_extents_m: tuple[float, float]
    margin_m: float


@dataclass(frozen=True)
class PlanProfile:
    """What a controller's plans promise, as the audit and a run's settings need it: the NMPC it
    plans with (N, tau, gamma, v bounds, robot circle, solver), the largest yaw rate it commands
    (rad/s), and, where its model has them, the body discs, the accelerations it plans within
    (m/s^2, rad/s^2) and the drive dead time it plans for (s); None: the paper's unicycle (one
    circle, instant velocity changes, instant stop). And the sensing latency it was told of (s)."""

    nmpc: NMPCConfig
    omega_cmd_max_radps: float
    body: BodyDiscs | None = None
    planned_accel: tuple[float, float] | None = None
    planned_dead_time_s: float | None = None
    planned_latency_s: float = 0.0  # the sensing latency its plans start from (s)


@dataclass(frozen=True)
class ControllerEntry:
    """One controller as the simulator and the tools know it.

    `configure` makes its configuration from a scenario's inputs, `build` a fresh controller from
    that configuration (configuring is cheap; building may compile NLPs), `profile` what its plans
    promise. `settings`: the configuration dataclass whose ranged fields (controllers.settings) a
    scenario may set under `controller.<settings_key>`; None: it takes none. `paper`: one of the
    paper's obstacle constraints, reproduced unchanged (the suite's, the bench's and the kinematic
    loop's default set). `avoids_obstacles`: False for a baseline with no obstacle constraint.
    `decay_rate`: gamma means something to it (it is shown in labels and
    varied in sweeps). `decay_slack`: s_h is one of its decision variables."""

    name: str
    summary: str
    configure: Callable[[ControllerInputs], Any]
    build: Callable[[Any], Controller]
    profile: Callable[[Any], PlanProfile]
    settings: type | None = None
    paper: bool = False
    avoids_obstacles: bool = True
    decay_rate: bool = True
    decay_slack: bool = False

    @property
    def settings_key(self) -> str:
        """The scenario key of its own settings: its name as an identifier (`husky_cbf`)."""
        return self.name.replace("-", "_")

    def make(self, inputs: ControllerInputs) -> Controller:
        """A fresh controller for these inputs."""
        return self.build(self.configure(inputs))


_ENTRIES: dict[str, ControllerEntry] = {}
_LOADED = False


def register(entry: ControllerEntry) -> ControllerEntry:
    """Add a controller (ValueError if its name is taken by another); returns it, so a package can
    write `ENTRY = register(ControllerEntry(...))`."""
    held = _ENTRIES.get(entry.name)
    if held is not None and held is not entry:
        raise ValueError(f"controller: {entry.name!r} is registered already")
    if not entry.name or not entry.settings_key.isidentifier():
        raise ValueError(f"controller: a name of letters, digits, '-' and '_', got {entry.name!r}")
    _ENTRIES[entry.name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove a controller registered in this process (a test's, when it is done)."""
    _ENTRIES.pop(name, None)


def _load() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    for module in BUILT_IN:
        importlib.import_module(module)
    for point in entry_points(group=ENTRY_POINT_GROUP):
        value = point.load()
        if isinstance(value, ControllerEntry):
            register(value)


def entries() -> tuple[ControllerEntry, ...]:
    """Every registered controller, the built-in ones first."""
    _load()
    return tuple(_ENTRIES.values())


def names() -> tuple[str, ...]:
    """Every registered controller's name."""
    return tuple(e.name for e in entries())


def paper_names(with_baseline: bool = True) -> tuple[str, ...]:
    """The paper's controllers (BT, CBF, Relax-CBF), and the unconstrained baseline unless not
    `with_baseline`."""
    return tuple(e.name for e in entries() if e.paper and (with_baseline or e.avoids_obstacles))


def entry(name: str) -> ControllerEntry:
    """The controller called `name`; ValueError naming the registered ones otherwise."""
    _load()
    found = _ENTRIES.get(name)
    if found is None:
        raise ValueError(f"controller: must be one of {', '.join(_ENTRIES)}, got {name!r}")
    return found
