"""The robot's published figures, each with the place it was taken from: read from its folder
(`assets/husky_a200/specs.yaml`, where every figure stands beside its source), the one place they
are written. Conflicts between sources are listed there (`known_discrepancies`); the choices made
for `assets/husky_a200/husky_a200.urdf` are derived here (:data:`HUSKY_MODEL`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from husky_sim.paths import ASSETS_DIR
from husky_sim.scenario_file import ScenarioFileError, read_scenario_data

#: The Husky's published figures with their sources.
SPECS_FILE: Path = ASSETS_DIR / "specs.yaml"

# Inertia tensors are stored as (ixx, ixy, ixz, iyy, iyz, izz) in kg*m^2, as in URDF.
InertiaTuple = tuple[float, float, float, float, float, float]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class SpecSheet:
    """Manufacturer specification table of the real robot ([MANUAL])."""

    length_m: float
    width_m: float
    height_m: float
    track_width_m: float
    wheelbase_m: float
    ground_clearance_m: float
    mass_kg: float
    max_payload_kg: float
    all_terrain_payload_kg: float
    max_speed_mps: float
    climb_grade_deg: float
    traversal_grade_deg: float
    effective_track_m: float
    encoder_ticks_per_m: float
    battery_capacity_ah: float
    battery_voltage_v: float


@dataclass(frozen=True)
class PublishedDescription:
    """Figures of Clearpath's own robot description (URDF/xacro)."""

    # Chassis collision envelope; base_link is the centre of the bottom plate.
    base_x_size_m: float
    base_y_size_m: float
    base_z_size_m: float
    upper_box_length_fraction: float
    # Wheel mounting: joint origins at (+-wheelbase/2, +-track/2, wheel_vertical_offset).
    wheelbase_m: float
    track_m: float
    wheel_vertical_offset_m: float
    # Wheels (13 in outdoor tyre).
    wheel_radius_m: float
    wheel_width_m: float
    wheel_diameter_m: float
    wheel_mass_kg: float
    wheel_inertia_radial_kgm2: float
    wheel_inertia_axle_kgm2: float
    wheel_friction_mu: float
    # Chassis inertial ("inertial_link", fixed to base_link at the origin).
    base_inertial_mass_kg: float
    base_inertial_com_m: Vec3
    base_inertia_kgm2: InertiaTuple
    # Decorations (meshes only upstream; positions relative to base_link).
    bumper_mount_x_m: float
    bumper_mount_z_m: float
    top_plate_mount_m: Vec3
    # Drive hardware limits (ros2_control hardware params in husky_macro.urdf.xacro).
    hardware_max_speed_mps: float
    hardware_max_accel_mps2: float


@dataclass(frozen=True)
class DiffDriveLimits:
    """diff_drive_controller parameters and velocity/acceleration limits."""

    wheel_separation_multiplier: float  # dimensionless (skid-steer slip compensation)
    wheel_radius_multiplier: float  # dimensionless
    linear_max_velocity_mps: float  # linear.x.max_velocity, m/s
    linear_max_acceleration_mps2: float  # linear.x.max_acceleration, m/s^2
    angular_max_velocity_radps: float  # angular.z.max_velocity, rad/s
    angular_max_acceleration_radps2: float  # angular.z.max_acceleration, rad/s^2
    wheel_separation_m: float | None = None  # explicit wheel_separation (None: read URDF)
    cmd_vel_timeout_s: float | None = None  # cmd_vel_timeout, s

    def effective_wheel_separation_m(self, track_m: float) -> float:
        """Separation the controller uses: (explicit or URDF track) * multiplier, in m."""
        base = self.wheel_separation_m if self.wheel_separation_m is not None else track_m
        return base * self.wheel_separation_multiplier


@dataclass(frozen=True)
class MotorSpec:
    """One side's gearmotor and its controller ([MOTOR])."""

    torque_constant_nm_per_a: float  # N m / A
    gear_ratio: float  # motor turns per wheel turn
    continuous_current_a: float  # rated continuous current (A)
    current_limit_a: float  # the motor controller's current limit (A)
    gearbox_efficiency: float  # output / input power


@dataclass(frozen=True)
class RobotSpecs:
    """Everything published about the robot, as its specs file holds it."""

    sources: dict[str, str]  # tag ([MANUAL], ...) -> where the figures were taken from
    spec_sheet: SpecSheet
    description: PublishedDescription
    ros1_diff_drive: DiffDriveLimits  # the simulated drive's defaults
    ros2_diff_drive: DiffDriveLimits
    motor: MotorSpec
    known_discrepancies: tuple[str, ...]


def _section(kind: type, data: Any, where: str) -> Any:
    """`kind` (a dataclass) from a mapping with exactly its fields; lists become tuples."""
    names = {f.name for f in fields(kind)}
    if not isinstance(data, dict) or set(data) != names:
        given = set(data) if isinstance(data, dict) else set()
        wrong = sorted(given - names) or sorted(names - given) or ["(not a mapping)"]
        raise ValueError(f"{where}: expected the fields of {kind.__name__}; check {', '.join(wrong)}")
    return kind(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


@functools.cache
def load_specs(path: Path = SPECS_FILE) -> RobotSpecs:
    """A robot's published figures from its specs file, read once per file (the simulator's
    constants here and the robot description share one copy); a missing or extra field is a
    one-line ValueError naming the file and the section."""
    try:
        data = read_scenario_data(path)
    except ScenarioFileError as exc:
        raise ValueError(str(exc)) from None
    drive = data.get("diff_drive", {})
    return RobotSpecs(
        sources=dict(data.get("sources", {})),
        spec_sheet=_section(SpecSheet, data.get("spec_sheet"), f"{path}: spec_sheet"),
        description=_section(PublishedDescription, data.get("description"), f"{path}: description"),
        ros1_diff_drive=_section(DiffDriveLimits, drive.get("ros1"), f"{path}: diff_drive.ros1"),
        ros2_diff_drive=_section(DiffDriveLimits, drive.get("ros2"), f"{path}: diff_drive.ros2"),
        motor=_section(MotorSpec, data.get("motor"), f"{path}: motor"),
        known_discrepancies=tuple(data.get("known_discrepancies", ())),
    )


@dataclass(frozen=True)
class HuskyModel:
    """Values actually written into ``assets/husky_a200/husky_a200.urdf``.

    Geometry is the published description unchanged. Mass is the spec-sheet 50 kg: the
    wheels keep their published 2.637 kg and the chassis gets the rest; the published
    chassis inertia tensor is scaled by (chassis mass / 46.034 kg), i.e. its radii of
    gyration are kept. Only its diagonal (the moments about the base_link axes, izz being
    the yaw inertia) is written: the small products of inertia would make PyBullet rotate
    the base inertial frame by ~5 deg (pitch) and ~1.2 deg (yaw), and
    ``getBasePositionAndOrientation`` reports that frame. The chassis COM keeps the
    published x and z but is put on the centre line (y = 0), see
    :data:`KNOWN_DISCREPANCIES`.
    """

    total_mass_kg: float
    wheel_mass_kg: float
    chassis_mass_kg: float
    chassis_com_m: Vec3
    chassis_inertia_kgm2: InertiaTuple
    wheel_inertia_kgm2: InertiaTuple
    wheel_radius_m: float
    wheel_width_m: float
    wheelbase_m: float
    track_m: float
    wheel_vertical_offset_m: float

    @property
    def base_link_height_m(self) -> float:
        """Height of the base_link origin above flat ground with the wheels resting, m."""
        return self.wheel_radius_m - self.wheel_vertical_offset_m

    @property
    def wheel_positions_m(self) -> dict[str, Vec3]:
        """Wheel joint origins in base_link, keyed by joint name, m."""
        hx, hy, z = self.wheelbase_m / 2.0, self.track_m / 2.0, self.wheel_vertical_offset_m
        return {
            "front_left_wheel": (hx, hy, z),
            "front_right_wheel": (hx, -hy, z),
            "rear_left_wheel": (-hx, hy, z),
            "rear_right_wheel": (-hx, -hy, z),
        }


def _build_model(sheet: SpecSheet, desc: PublishedDescription) -> HuskyModel:
    """Derive the modelling choices from the published figures (see :class:`HuskyModel`)."""
    chassis_mass = sheet.mass_kg - 4.0 * desc.wheel_mass_kg
    scale = chassis_mass / desc.base_inertial_mass_kg
    ixx, _, _, iyy, _, izz = (round(v * scale, 6) for v in desc.base_inertia_kgm2)
    inertia: InertiaTuple = (ixx, 0.0, 0.0, iyy, 0.0, izz)  # products of inertia dropped
    radial, axle = desc.wheel_inertia_radial_kgm2, desc.wheel_inertia_axle_kgm2
    com = desc.base_inertial_com_m
    return HuskyModel(
        total_mass_kg=sheet.mass_kg,
        wheel_mass_kg=desc.wheel_mass_kg,
        chassis_mass_kg=round(chassis_mass, 6),
        chassis_com_m=(com[0], 0.0, com[2]),
        chassis_inertia_kgm2=inertia,
        wheel_inertia_kgm2=(radial, 0.0, 0.0, axle, 0.0, radial),
        wheel_radius_m=desc.wheel_radius_m,
        wheel_width_m=desc.wheel_width_m,
        wheelbase_m=desc.wheelbase_m,
        track_m=desc.track_m,
        wheel_vertical_offset_m=desc.wheel_vertical_offset_m,
    )


HUSKY = load_specs()
HUSKY_SPEC_SHEET = HUSKY.spec_sheet
HUSKY_DESCRIPTION = HUSKY.description
ROS1_DIFF_DRIVE = HUSKY.ros1_diff_drive  # [CONTROL]
ROS2_DIFF_DRIVE = HUSKY.ros2_diff_drive  # [CONTROL2]
HUSKY_MODEL = _build_model(HUSKY_SPEC_SHEET, HUSKY_DESCRIPTION)

# Convenience constants (the figures the simulator uses).
WHEEL_RADIUS_M: float = HUSKY_DESCRIPTION.wheel_radius_m  # [URDF]
WHEEL_WIDTH_M: float = HUSKY_DESCRIPTION.wheel_width_m  # [URDF]
TRACK_WIDTH_M: float = HUSKY_DESCRIPTION.track_m  # [URDF] wheel centre to wheel centre
WHEELBASE_M: float = HUSKY_DESCRIPTION.wheelbase_m  # [URDF] and [MANUAL] agree
TOTAL_MASS_KG: float = HUSKY_SPEC_SHEET.mass_kg  # [MANUAL]
MAX_SPEED_MPS: float = HUSKY_SPEC_SHEET.max_speed_mps  # [MANUAL]
WHEEL_SEPARATION_MULTIPLIER: float = ROS1_DIFF_DRIVE.wheel_separation_multiplier  # [CONTROL]
WHEEL_RADIUS_MULTIPLIER: float = ROS1_DIFF_DRIVE.wheel_radius_multiplier  # [CONTROL]
LINEAR_MAX_VELOCITY_MPS: float = ROS1_DIFF_DRIVE.linear_max_velocity_mps  # [CONTROL]
LINEAR_MAX_ACCELERATION_MPS2: float = ROS1_DIFF_DRIVE.linear_max_acceleration_mps2  # [CONTROL]
ANGULAR_MAX_VELOCITY_RADPS: float = ROS1_DIFF_DRIVE.angular_max_velocity_radps  # [CONTROL]
ANGULAR_MAX_ACCELERATION_RADPS2: float = ROS1_DIFF_DRIVE.angular_max_acceleration_radps2  # [CONTROL]
MOTOR_TORQUE_CONSTANT_NM_PER_A: float = HUSKY.motor.torque_constant_nm_per_a  # [MOTOR]
MOTOR_GEAR_RATIO: float = HUSKY.motor.gear_ratio  # [MOTOR]
MOTOR_CONTINUOUS_CURRENT_A: float = HUSKY.motor.continuous_current_a  # [MOTOR]
MOTOR_CURRENT_LIMIT_A: float = HUSKY.motor.current_limit_a  # [MOTOR]
MOTOR_GEARBOX_EFFICIENCY: float = HUSKY.motor.gearbox_efficiency  # ours, see the specs file
KNOWN_DISCREPANCIES: tuple[str, ...] = HUSKY.known_discrepancies
