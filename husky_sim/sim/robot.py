"""The Husky A200 body in a PyBullet world: loading, wheel friction, motors and state readout.

Pose is that of base_link (PyBullet reports the base's inertial frame, offset from base_link by the
chassis centre of mass); yaw in (-pi, pi]. Wheels run in velocity control with a torque limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.geometry import DEFAULT_URDF, RobotGeometry, load_geometry
from husky_sim.sim.specs import HUSKY_DESCRIPTION


@dataclass(frozen=True)
class WheelFriction:
    """Wheel contact parameters. PyBullet multiplies the two bodies' coefficients at a contact,
    so with ground friction mu_g the effective longitudinal coefficient is mu_g x longitudinal and
    the lateral one mu_g x longitudinal x lateral_scale (anisotropic friction along the axle)."""

    longitudinal: float = 1.0  # wheel friction coefficient ([WHEEL]: mu = 1.0)
    lateral_scale: float = 1.0  # lateral / longitudinal ratio (< 1: tyres slide sideways easier)
    rolling: float = 0.0  # rolling friction (m)
    spinning: float = 0.0  # torsional friction (m)

    def __post_init__(self) -> None:
        if not self.longitudinal > 0:
            raise ValueError(f"wheel_friction.longitudinal: must be > 0, got {self.longitudinal}")
        if not self.lateral_scale > 0:
            raise ValueError(f"wheel_friction.lateral_scale: must be > 0, got {self.lateral_scale}")


#: Height (m) of the payload box (payload_inertia): our choice, the manual gives only the mass.
PAYLOAD_HEIGHT_M = 0.10


def payload_inertia(payload_kg: float, com_m: tuple[float, float, float]) -> np.ndarray:
    """Diagonal inertia (kg m^2) that a payload adds about the chassis centre of mass `com_m` (m,
    in base_link): a uniform box as long and wide as the chassis ([URDF] base_x_size x base_y_size)
    and PAYLOAD_HEIGHT_M tall, resting on its top (base_z_size), by the parallel-axis theorem.
    Products of inertia are dropped, as for the chassis."""
    d = HUSKY_DESCRIPTION
    size = np.array([d.base_x_size_m, d.base_y_size_m, PAYLOAD_HEIGHT_M])
    offset = np.array([0.0, 0.0, d.base_z_size_m + 0.5 * PAYLOAD_HEIGHT_M]) - np.asarray(com_m)
    own = payload_kg / 12.0 * (np.sum(size**2) - size**2)  # (b^2 + c^2, a^2 + c^2, a^2 + b^2) m / 12
    shifted = payload_kg * (float(offset @ offset) - offset**2)
    return own + shifted


class HuskyRobot:
    """A Husky loaded into a PyBullet client (DIRECT), driven through its four wheel joints."""

    def __init__(
        self,
        client: int,
        start: tuple[float, float, float],
        friction: WheelFriction | None = None,
        payload_kg: float = 0.0,
        urdf_path=DEFAULT_URDF,
    ) -> None:
        self.client = client
        self.geometry: RobotGeometry = load_geometry(urdf_path)
        x, y, yaw = start
        self.body = p.loadURDF(
            str(urdf_path),
            basePosition=[x, y, self.geometry.base_height_m + 1e-3],
            baseOrientation=p.getQuaternionFromEuler([0.0, 0.0, yaw]),
            flags=p.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=client,
        )
        joints = {
            p.getJointInfo(self.body, j, physicsClientId=client)[1].decode(): j
            for j in range(p.getNumJoints(self.body, physicsClientId=client))
        }
        self.left_joints = [joints[n] for n in self.geometry.left_wheel_joint_names]
        self.right_joints = [joints[n] for n in self.geometry.right_wheel_joint_names]
        self.wheel_joints = self.left_joints + self.right_joints
        friction = friction or WheelFriction()
        for j in self.wheel_joints:
            p.changeDynamics(
                self.body,
                j,
                lateralFriction=friction.longitudinal,
                rollingFriction=friction.rolling,
                spinningFriction=friction.spinning,
                anisotropicFriction=[1.0, friction.lateral_scale, 1.0],
                physicsClientId=client,
            )
        if payload_kg < 0:
            raise ValueError(f"payload_kg: must be >= 0 kg, got {payload_kg}")
        if payload_kg > 0:
            # PyBullet recomputes a base's inertia from its collision boxes as a solid when only its
            # mass is changed (a 1 g payload made the chassis's yaw inertia 1.74 -> 4.30 kg m^2, and
            # the loaded Husky barely turned), so the inertia is set too: the chassis's own plus
            # the payload's. The centre of mass stays the chassis's (PyBullet cannot move it).
            info = p.getDynamicsInfo(self.body, -1, physicsClientId=client)
            base_mass, base_inertia, com = info[0], np.array(info[2]), info[3]
            p.changeDynamics(
                self.body,
                -1,
                mass=base_mass + payload_kg,
                localInertiaDiagonal=(base_inertia + payload_inertia(payload_kg, com)).tolist(),
                physicsClientId=client,
            )
        self._inertial_inv = p.invertTransform(*p.getDynamicsInfo(self.body, -1, physicsClientId=client)[3:5])
        self._wheel_command: tuple[float, float, float] | None = None
        self.command_wheels(0.0, 0.0, 1.0)

    def command_wheels(self, left_radps: float, right_radps: float, torque_limit_nm: float) -> None:
        """Velocity-control targets for the left and right wheel pairs (rad/s). The engine keeps a
        motor's target until it is set again, so an unchanged command is not sent again."""
        command = (left_radps, right_radps, torque_limit_nm)
        if command == self._wheel_command:
            return
        self._wheel_command = command
        targets = [left_radps] * len(self.left_joints) + [right_radps] * len(self.right_joints)
        p.setJointMotorControlArray(
            self.body,
            self.wheel_joints,
            p.VELOCITY_CONTROL,
            targetVelocities=targets,
            forces=[torque_limit_nm] * len(targets),
            physicsClientId=self.client,
        )

    def _base_link(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """base_link's position (m) and quaternion, from PyBullet's centre-of-mass frame."""
        com_pos, com_orn = p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        return p.multiplyTransforms(com_pos, com_orn, *self._inertial_inv)

    def pose(self) -> np.ndarray:
        """base_link [x (m), y (m), yaw (rad)]."""
        pos, orn = self._base_link()
        return np.array([pos[0], pos[1], p.getEulerFromQuaternion(orn)[2]])

    def position_xy(self) -> tuple[float, float]:
        """base_link's x and y (m), as in `pose` (read every physics step by the clearance check)."""
        pos, _ = self._base_link()
        return pos[0], pos[1]

    def base_com_pose(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """PyBullet's base frame (centre of mass): position (m) and quaternion (x, y, z, w)."""
        return p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)

    def body_velocity(self) -> np.ndarray:
        """Achieved [v (m/s) along the heading, yaw rate (rad/s)]."""
        lin, ang = p.getBaseVelocity(self.body, physicsClientId=self.client)
        yaw = self.pose()[2]
        return np.array([lin[0] * math.cos(yaw) + lin[1] * math.sin(yaw), ang[2]])

    def wheel_speeds(self) -> np.ndarray:
        """Measured wheel speeds (rad/s) in the order left joints, right joints."""
        states = p.getJointStates(self.body, self.wheel_joints, physicsClientId=self.client)
        return np.array([s[1] for s in states])
