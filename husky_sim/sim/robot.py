"""The Husky A200 body in a PyBullet world: loading, the wheels on the ground (our tyre force, or
PyBullet's Coulomb friction for the uncalibrated plant), motors and state readout.

Pose is that of base_link (PyBullet reports the base's inertial frame, offset from base_link by the
chassis centre of mass); yaw in (-pi, pi]. Wheels run in velocity control at the speed drive_wheels
chooses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.geometry import RobotGeometry
from husky_sim.sim.robot_description import RobotDescription, load_robot
from husky_sim.sim.specs import PublishedDescription
from husky_sim.sim.tyre import TyreContact, tyre_force

#: Height (m) of the payload box (payload_inertia): our choice, the manual gives only the mass.
PAYLOAD_HEIGHT_M = 0.10


def payload_inertia(
    payload_kg: float, com_m: tuple[float, float, float], d: PublishedDescription
) -> np.ndarray:
    """Diagonal inertia (kg m^2) that a payload adds about the chassis centre of mass `com_m` (m,
    in base_link): a uniform box as long and wide as the chassis ([URDF] base_x_size x base_y_size)
    and PAYLOAD_HEIGHT_M tall, resting on its top (base_z_size), by the parallel-axis theorem.
    Products of inertia are dropped, as for the chassis."""
    size = np.array([d.base_x_size_m, d.base_y_size_m, PAYLOAD_HEIGHT_M])
    offset = np.array([0.0, 0.0, d.base_z_size_m + 0.5 * PAYLOAD_HEIGHT_M]) - np.asarray(com_m)
    own = payload_kg / 12.0 * (np.sum(size**2) - size**2)  # (b^2 + c^2, a^2 + c^2, a^2 + b^2) m / 12
    shifted = payload_kg * (float(offset @ offset) - offset**2)
    return own + shifted


def _rotate(q: tuple[float, ...], v: tuple[float, ...]) -> tuple[float, float, float]:
    """Vector v rotated by the unit quaternion q = (x, y, z, w) (plain floats)."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (qy * vz - qz * vy), 2.0 * (qz * vx - qx * vz), 2.0 * (qx * vy - qy * vx)
    return (
        vx + qw * tx + qy * tz - qz * ty,
        vy + qw * ty + qz * tx - qx * tz,
        vz + qw * tz + qx * ty - qy * tx,
    )


#: Torque (N m) the joint motors may use to hold the speed drive_wheels chose on the tyre contact:
#: that speed already respects the motor's limit, so the hold only overcomes the wheel's inertia.
HOLD_TORQUE_NM = 1000.0


@dataclass(frozen=True)
class _WheelContact:
    """One wheel on the ground: normal load (N), contact point (m), the unit vectors along and
    across the wheel on the ground plane, and its hub's velocity along and across it (m/s)."""

    link: int
    side: int  # 0 left, 1 right
    normal_n: float
    point: tuple[float, float, float]
    long_x: float
    long_y: float
    lat_x: float
    lat_y: float
    v_long: float
    v_lat: float


class SkidSteerRobot:
    """A robot (its folder: the Husky A200 unless told) loaded into a PyBullet client (DIRECT),
    driven through its four wheel joints."""

    def __init__(
        self,
        client: int,
        start: tuple[float, float, float],
        tyre: TyreContact | None = None,
        payload_kg: float = 0.0,
        coulomb: bool = False,
        robot: RobotDescription | None = None,
    ) -> None:
        self.client = client
        self.description = robot if robot is not None else load_robot()
        self.geometry: RobotGeometry = self.description.geometry
        x, y, yaw = start
        self.body = p.loadURDF(
            str(self.description.urdf),
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
        self.tyre = tyre or TyreContact()
        self.coulomb = coulomb
        # With the tyre model the engine gives the wheels only normal forces and drive_wheels
        # supplies the rest; with `coulomb` (the uncalibrated plant) the engine's friction does it
        # all, mu = 1 x the ground plane's (WorldConfig.ground_friction).
        for j in self.wheel_joints:
            p.changeDynamics(
                self.body,
                j,
                lateralFriction=1.0 if coulomb else 0.0,
                rollingFriction=0.0,
                spinningFriction=0.0,
                anisotropicFriction=[1.0, 1.0, 1.0],
                physicsClientId=client,
            )
        self._wheel_axes = [
            tuple(p.getJointInfo(self.body, j, physicsClientId=client)[13]) for j in self.wheel_joints
        ]
        self._wheel_index = {j: i for i, j in enumerate(self.wheel_joints)}
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
                localInertiaDiagonal=(
                    base_inertia + payload_inertia(payload_kg, com, self.description.specs.description)
                ).tolist(),
                physicsClientId=client,
            )
        self._inertial_inv = p.invertTransform(*p.getDynamicsInfo(self.body, -1, physicsClientId=client)[3:5])
        self._wheel_command: tuple[float, float, float] | None = None
        self._side_torques = (0.0, 0.0)
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

    def drive_wheels(self, left_radps: float, right_radps: float, side_torque_limit_nm: float) -> None:
        """Wheel speed targets (rad/s) for the next physics step, each side's motor limited to
        `side_torque_limit_nm` (N m at the wheels, summed over the side's wheels). Call it before
        every physics step (the engine clears external forces after each)."""
        if self.coulomb:  # the uncalibrated plant: the engine's velocity motors and friction
            self.command_wheels(left_radps, right_radps, side_torque_limit_nm / len(self.left_joints))
            return
        contacts = self._wheel_contacts()
        r_eff = self.tyre.rolling_radius_scale * self.geometry.wheel_radius_m
        speeds, torques = [left_radps, right_radps], [0.0, 0.0]
        for side in (0, 1):
            wheels = [c for c in contacts if c.side == side]
            if wheels:
                speeds[side], torques[side] = self._side_speed(
                    wheels, speeds[side], side_torque_limit_nm, r_eff
                )
        self._side_torques = (torques[0], torques[1])
        self.command_wheels(speeds[0], speeds[1], HOLD_TORQUE_NM)
        cid = self.client
        for c in contacts:
            f_long, f_lat = tyre_force(self.tyre, c.normal_n, c.v_long - r_eff * speeds[c.side], c.v_lat)
            force = (f_long * c.long_x + f_lat * c.lat_x, f_long * c.long_y + f_lat * c.lat_y, 0.0)
            p.applyExternalForce(self.body, c.link, force, c.point, p.WORLD_FRAME, physicsClientId=cid)

    def _side_speed(
        self, wheels: list[_WheelContact], target_radps: float, limit_nm: float, r_eff: float
    ) -> tuple[float, float]:
        """The speed (rad/s) of one side's wheels (one motor, one belt) and the torque (N m) its
        motor gives: the target, unless the tyres there need more than the limit; then the speed at
        which the tyres take exactly the limit (quasi-static in the wheels' spin: an explicit tyre
        force on a freely spinning wheel is too stiff for one physics step, and oscillated under a
        payload; the wheels' spin-up is in the drive's lag)."""
        radius = self.geometry.wheel_radius_m

        def motor_torque(speed: float) -> float:  # rises with speed: the tyres push back harder
            total = 0.0
            for c in wheels:
                total -= radius * tyre_force(self.tyre, c.normal_n, c.v_long - r_eff * speed, c.v_lat)[0]
            return -total

        need = motor_torque(target_radps)
        if abs(need) <= limit_nm:
            return target_radps, need
        goal = math.copysign(limit_nm, need)
        # bracket: from the target towards free rolling, where the tyres need no torque
        # (the torque rises with speed: to lower it, step down in speed when it is positive)
        other = sum(c.v_long for c in wheels) / (len(wheels) * r_eff)
        step = math.copysign(max(abs(other - target_radps), 0.1), -need)
        for _ in range(60):  # the tyres' torque is bounded by mu N r: the goal lies within reach
            if (motor_torque(target_radps + step) - goal) * (need - goal) <= 0.0:
                break
            step *= 2.0
        lo, hi = target_radps, target_radps + step
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if (motor_torque(mid) - goal) * (need - goal) > 0.0:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi), goal

    def _wheel_contacts(self) -> list[_WheelContact]:
        """Each wheel touching ground-like support: its normal load from the last step's contacts
        and its hub velocity along and across the wheel, on the ground plane (normal taken as +z)."""
        cid = self.client
        loads: dict[int, list[float]] = {}  # wheel link -> [normal load N, N-weighted x, y, z]
        for c in p.getContactPoints(bodyA=self.body, physicsClientId=cid):
            link, force = c[3], c[9]
            if link not in self._wheel_index or c[7][2] < 0.5 or force <= 0.0:
                continue
            acc = loads.setdefault(link, [0.0, 0.0, 0.0, 0.0])
            pos = c[5]
            acc[0] += force
            acc[1] += force * pos[0]
            acc[2] += force * pos[1]
            acc[3] += force * pos[2]
        if not loads:
            return []
        links = sorted(loads)
        states = p.getLinkStates(self.body, links, computeLinkVelocity=1, physicsClientId=cid)
        contacts = []
        for link, state in zip(links, states, strict=True):
            normal, px, py, pz = loads[link]
            index = self._wheel_index[link]
            ax, ay, _ = _rotate(state[5], self._wheel_axes[index])  # the axle in the world
            norm = math.hypot(ax, ay)
            if norm < 1e-6:
                continue  # axle upright: the wheel lies on its side
            lat_x, lat_y = ax / norm, ay / norm
            long_x, long_y = lat_y, -lat_x  # lateral x up: along the wheel's rolling direction
            vx, vy, _ = state[6]
            contacts.append(
                _WheelContact(
                    link=link,
                    side=0 if index < len(self.left_joints) else 1,
                    normal_n=normal,
                    point=(px / normal, py / normal, pz / normal),
                    long_x=long_x,
                    long_y=long_y,
                    lat_x=lat_x,
                    lat_y=lat_y,
                    v_long=vx * long_x + vy * long_y,
                    v_lat=vx * lat_x + vy * lat_y,
                )
            )
        return contacts

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

    def side_torques(self) -> tuple[float, float]:
        """Motor torque (N m at the wheels, summed over a side's wheels) of the left and of the right
        side in the last physics step: on the tyre contact what drive_wheels gave the tyres, on the
        Coulomb contact what the engine's motors applied."""
        if not self.coulomb:
            return self._side_torques
        states = p.getJointStates(self.body, self.wheel_joints, physicsClientId=self.client)
        n = len(self.left_joints)
        return sum(s[3] for s in states[:n]), sum(s[3] for s in states[n:])

    def wheel_speeds(self) -> np.ndarray:
        """Measured wheel speeds (rad/s) in the order left joints, right joints."""
        states = p.getJointStates(self.body, self.wheel_joints, physicsClientId=self.client)
        return np.array([s[1] for s in states])
