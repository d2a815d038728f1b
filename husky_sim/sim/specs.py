"""Published figures for the Clearpath Husky A200, each with the place it was taken from.

Only numbers are taken from these sources; no code was copied.

Sources
-------
[MANUAL]    Clearpath Robotics, "Husky A200 User Manual", section "System Specifications"
            and "Robot Equations". Repository ``clearpathrobotics/cpr-documentation``,
            file ``docs_robots/outdoor_robots/husky/a200/user_manual_husky.mdx``
            (commit b4e8e8e052cd64416ea14ac763b0c00f5809e897), published at
            docs.clearpathrobotics.com (Husky A200 > User Manual). The same effective
            track (0.555 m) is on p. 9 of the 2011 PDF manual:
            https://www.manualslib.com/manual/3073500/Clearpath-Husky-A200.html?page=9
[URDF]      Repository ``husky/husky``, ``husky_description/urdf/husky.urdf.xacro``
            (commit 03cff3700a7009745b66cd842d2d80eed7433849) and
            ``husky_description/urdf/husky_macro.urdf.xacro``
            (commit da175a7ce54eb2f4dbc56ddf9bc3a0c383288c9e): base size, wheel mounting
            positions, wheel size, ``inertial_link``; ros2_control hardware parameters.
            Identical numbers in ``clearpathrobotics/clearpath_common``,
            ``clearpath_platform_description/urdf/a200/a200.urdf.xacro``.
[WHEEL]     Repository ``husky/husky``, ``husky_description/urdf/wheel.urdf.xacro``
            (commit 0f3d22501a5e919024e08569ae6c461a80ecfbf6): wheel mass, inertia, friction.
            Axle orientation of that inertia: husky/husky issue #34 "Wheel inertias flipped"
            (https://github.com/husky/husky/issues/34), fixed upstream by swapping iyy/izz,
            and ``clearpathrobotics/clearpath_common``
            ``clearpath_platform_description/urdf/a200/drivetrain/wheels/outdoor.urdf.xacro``
            (commit 3197f4475902c7a5755b3b4ea0b305ed097ab757), which puts the axle on y.
[DECOR]     Repository ``husky/husky``, ``husky_description/urdf/decorations.urdf.xacro``
            (commit 1a43fa4b38c7db68c0425b0401002f378e53bd0d): bumper and top-plate mounts.
[CONTROL]   Repository ``husky/husky``, ``husky_control/config/control.yaml``
            (commit a087a3dcc5b95b2350a3b1a851f551f8078fa539): ROS 1 diff_drive_controller.
[CONTROL2]  Repository ``clearpathrobotics/clearpath_common``,
            ``clearpath_control/config/a200/control.yaml``
            (commit 077ed1c954ee51cf286d60569789057a0d7f0cb0): ROS 2 diff_drive_controller.
[MOTOR]     The A200's drive (one gearmotor per side, both wheels of a side on one belt): Midwest
            Motion Products S22-346F-24V with a GP52-079 planetary gearbox (about 78.71:1), 10.7 A
            continuous, behind a motor controller that limits current at 26 A, as listed for the
            A200 by Clearpath; torque constant about 0.0445 N m/A as identified by McCormick et
            al. 2022 (Husky parameter identification). The gearbox efficiency is ours (below).
[PR36]      husky/husky pull request #36 (https://github.com/husky/husky/pull/36): history of
            the ``inertial_link`` values (an earlier 33.455 kg set had its COM offset on x).

Conflicts between sources are listed in :data:`KNOWN_DISCREPANCIES`; the choices made for
``assets/husky_a200/husky_a200.urdf`` are in :data:`HUSKY_MODEL`.
"""

from __future__ import annotations

from dataclasses import dataclass

# Inertia tensors are stored as (ixx, ixy, ixz, iyy, iyz, izz) in kg*m^2, as in URDF.
InertiaTuple = tuple[float, float, float, float, float, float]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class SpecSheet:
    """Manufacturer specification table of the real robot ([MANUAL])."""

    length_m: float = 0.990  # [MANUAL] Dimension, Length: 990 mm (overall, bumpers included)
    width_m: float = 0.670  # [MANUAL] Dimension, Width: 670 mm (overall, wheels included)
    height_m: float = 0.390  # [MANUAL] Dimension, Height: 390 mm (ground to top)
    track_width_m: float = 0.550  # [MANUAL] Track Width: 550 mm (see KNOWN_DISCREPANCIES)
    wheelbase_m: float = 0.512  # [MANUAL] Wheelbase Length: 512 mm
    ground_clearance_m: float = 0.130  # [MANUAL] Ground Clearance: 130 mm
    mass_kg: float = 50.0  # [MANUAL] Mass: 50 kg
    max_payload_kg: float = 75.0  # [MANUAL] Maximum Payload: 75 kg (flat terrain, wide turns)
    all_terrain_payload_kg: float = 20.0  # [MANUAL] All-terrain Payload: 20 kg
    max_speed_mps: float = 1.0  # [MANUAL] Speed, Maximum: 1 m/s
    climb_grade_deg: float = 45.0  # [MANUAL] Climb Grade: 45 deg
    traversal_grade_deg: float = 30.0  # [MANUAL] Traversal Grade / Sideslope: 30 deg
    effective_track_m: float = 0.555  # [MANUAL] "Robot Equations": effective track W = 0.555 m
    encoder_ticks_per_m: float = 78_000.0  # [MANUAL] Wheel Encoders: 78,000 ticks/m
    battery_capacity_ah: float = 20.0  # [MANUAL] Battery: 20 Ah @ 24 V sealed lead-acid
    battery_voltage_v: float = 24.0  # [MANUAL] Battery: 24 V


@dataclass(frozen=True)
class PublishedDescription:
    """Figures of Clearpath's own robot description (URDF/xacro)."""

    # Chassis collision envelope; base_link is the centre of the bottom plate.
    base_x_size_m: float = 0.9874  # [URDF] base_x_size
    base_y_size_m: float = 0.5709  # [URDF] base_y_size
    base_z_size_m: float = 0.2475  # [URDF] base_z_size
    upper_box_length_fraction: float = 0.8  # [URDF] upper collision box is base_x_size*4/5 long
    # Wheel mounting: joint origins at (+-wheelbase/2, +-track/2, wheel_vertical_offset).
    wheelbase_m: float = 0.5120  # [URDF] wheelbase (front-rear axle distance)
    track_m: float = 0.5708  # [URDF] track (left-right wheel centre distance)
    wheel_vertical_offset_m: float = 0.03282  # [URDF] axle height above base_link
    # Wheels (13 in outdoor tyre).
    wheel_radius_m: float = 0.1651  # [URDF] wheel_radius; [WHEEL] outdoor.urdf.xacro
    wheel_width_m: float = 0.1143  # [URDF] wheel_length; [WHEEL] outdoor wheel width
    wheel_diameter_m: float = 0.3302  # [URDF] husky_macro ros2_control param wheel_diameter
    wheel_mass_kg: float = 2.637  # [WHEEL] wheel link mass
    wheel_inertia_radial_kgm2: float = 0.02467  # [WHEEL] ixx = izz (about a diameter)
    wheel_inertia_axle_kgm2: float = 0.04411  # [WHEEL] iyy (about the axle, after issue #34)
    wheel_friction_mu: float = 1.0  # [WHEEL] Gazebo mu1 = mu2 = 1.0
    # Chassis inertial ("inertial_link", fixed to base_link at the origin).
    base_inertial_mass_kg: float = 46.034  # [URDF] inertial_link mass
    base_inertial_com_m: Vec3 = (-0.00065, -0.085, 0.062)  # [URDF] inertial_link origin
    base_inertia_kgm2: InertiaTuple = (  # [URDF] inertial_link inertia about its COM
        0.6022,  # ixx
        -0.02364,  # ixy
        -0.1197,  # ixz
        1.7386,  # iyy
        -0.001544,  # iyz
        2.0296,  # izz
    )
    # Decorations (meshes only upstream; positions relative to base_link).
    bumper_mount_x_m: float = 0.48  # [DECOR] front/rear bumper joints at x = +-0.48 m
    bumper_mount_z_m: float = 0.091  # [DECOR] bumper joints at z = 0.091 m
    top_plate_mount_m: Vec3 = (0.0812, 0.0, 0.245)  # [DECOR] top_plate_joint origin
    # Drive hardware limits (ros2_control hardware params in husky_macro.urdf.xacro).
    hardware_max_speed_mps: float = 1.0  # [URDF] husky_macro param max_speed
    hardware_max_accel_mps2: float = 5.0  # [URDF] husky_macro param max_accel


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


# [CONTROL] husky/husky husky_control/config/control.yaml (ROS 1). The controller reads the
# separation from the URDF (track 0.5708 m). All limits have has_*_limits: true.
ROS1_DIFF_DRIVE = DiffDriveLimits(
    wheel_separation_multiplier=1.875,  # [CONTROL] wheel_separation_multiplier
    wheel_radius_multiplier=1.0,  # [CONTROL] wheel_radius_multiplier
    linear_max_velocity_mps=1.0,  # [CONTROL] linear.x.max_velocity (see discrepancies)
    linear_max_acceleration_mps2=3.0,  # [CONTROL] linear.x.max_acceleration
    angular_max_velocity_radps=2.0,  # [CONTROL] angular.z.max_velocity
    angular_max_acceleration_radps2=6.0,  # [CONTROL] angular.z.max_acceleration
    wheel_separation_m=None,
    cmd_vel_timeout_s=0.25,  # [CONTROL] cmd_vel_timeout
)

# [CONTROL2] clearpath_common clearpath_control/config/a200/control.yaml (ROS 2).
ROS2_DIFF_DRIVE = DiffDriveLimits(
    wheel_separation_multiplier=1.875,  # [CONTROL2] wheel_separation_multiplier
    wheel_radius_multiplier=1.0,  # [CONTROL2] left/right_wheel_radius_multiplier
    linear_max_velocity_mps=1.0,  # [CONTROL2] linear.x.max_velocity
    linear_max_acceleration_mps2=1.0,  # [CONTROL2] linear.x.max_acceleration
    angular_max_velocity_radps=1.0,  # [CONTROL2] angular.z.max_velocity
    angular_max_acceleration_radps2=1.0,  # [CONTROL2] angular.z.max_acceleration
    wheel_separation_m=0.555,  # [CONTROL2] wheel_separation (= MANUAL effective track)
    cmd_vel_timeout_s=0.5,  # [CONTROL2] cmd_vel_timeout
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


HUSKY_SPEC_SHEET = SpecSheet()
HUSKY_DESCRIPTION = PublishedDescription()
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
ANGULAR_MAX_ACCELERATION_RADPS2: float = (
    ROS1_DIFF_DRIVE.angular_max_acceleration_radps2  # [CONTROL]
)

# [MOTOR] one side's gearmotor
MOTOR_TORQUE_CONSTANT_NM_PER_A: float = 0.0445  # [MOTOR] McCormick et al. 2022
MOTOR_GEAR_RATIO: float = 78.71  # [MOTOR] GP52-079 planetary gearbox
MOTOR_CONTINUOUS_CURRENT_A: float = 10.7  # [MOTOR] rated continuous current
MOTOR_CURRENT_LIMIT_A: float = 26.0  # [MOTOR] motor controller current limit
#: Not published: three planetary stages at about 0.9 each (0.9^3 = 0.73), the usual figure for a
#: three-stage planetary gearhead; the motor currents of the wet-grass recording are checked
#: against it (tests/calibration).
MOTOR_GEARBOX_EFFICIENCY: float = 0.73

KNOWN_DISCREPANCIES: tuple[str, ...] = (
    "Mass: [MANUAL] says 50 kg; [URDF] inertial_link 46.034 kg + 4 x 2.637 kg wheels = "
    "56.582 kg (+13 %). The model uses 50 kg and scales the chassis inertia.",
    "Chassis products of inertia: [URDF] ixy = -0.02364, ixz = -0.1197, iyz = -0.001544 "
    "kg*m^2 (principal axes tilted ~5 deg). The model keeps only the (scaled) diagonal so "
    "the PyBullet base inertial frame stays aligned with base_link.",
    "Chassis COM: [URDF] puts it at y = -0.085 m (8.5 cm to the right); [PR36] shows an "
    "earlier value with the ~0.087 m offset on x instead, so the lateral offset is likely an "
    "axis mix-up. The model uses y = 0 (published x = -0.00065 m, z = 0.062 m kept).",
    "Track: [URDF] 0.5708 m between wheel centres; [MANUAL] table says 550 mm; [MANUAL] "
    "robot equations and [CONTROL2] use an effective track of 0.555 m. Geometry uses 0.5708.",
    "Wheel inertia: the original [WHEEL] file had the 0.04411 kg*m^2 term on z; upstream "
    "issue #34 swapped it onto y (the axle). Solid-cylinder values would be 0.0208/0.0359.",
    "Linear max velocity: one stored revision of [CONTROL] "
    "(0053ec4236b79893c883d6679aff29f6f428dbdb) has 3.0 m/s, another "
    "(a087a3dcc5b95b2350a3b1a851f551f8078fa539) has 1.0 m/s; 1.0 m/s matches [MANUAL].",
    "ROS 2 limits ([CONTROL2]) are lower: 1.0 m/s^2 linear, 1.0 rad/s and 1.0 rad/s^2 angular.",
    "Width: wheels outer faces span 0.5708 + 0.1143 = 0.685 m vs [MANUAL] 0.670 m; height of "
    "the collision model is 0.380 m vs [MANUAL] 0.390 m (top plate/rails not modelled).",
)
