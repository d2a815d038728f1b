"""Settings of the ROS 2 node and the rehearsal robot: topic names, frames, QoS profile names,
clock and DDS domain (ROS_DOMAIN_ID, leases of private domains). No DDS here, so the command line
can build its options without loading Cyclone DDS."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, fields
from pathlib import Path

#: DDS domain ids Cyclone DDS can map to ports (ROS 2 recommends 0 to 101 on Linux).
MAX_DOMAIN_ID = 232

#: The QoS profiles a topic's setting may name (ROS 2's names; each transport makes them).
QOS_PROFILE_NAMES = ("sensor_data", "default", "clock")

#: The transports a node can run on: Cyclone DDS from Python (no ROS install), or rclpy on
#: whatever middleware ROS 2 is configured for (RMW_IMPLEMENTATION; Fast DDS by default).
TRANSPORTS = ("cyclonedds", "rclpy")

#: Distributions whose message definitions the Cyclone DDS transport can speak
#: (husky_sim.ros2.messages.ROS_DISTROS has their type stores; the first is the default for the
#: node's own topics, whose messages are the same on the wire in all of them).
ROS_DISTRO_NAMES = ("humble", "jazzy", "kilted")


def domain_id_from_env(environ: dict[str, str] | None = None) -> int:
    """ROS_DOMAIN_ID as ROS 2 reads it (0 when unset); one-line ValueError when out of range."""
    text = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError:
        raise ValueError(
            f"ROS_DOMAIN_ID: expected an integer in [0, {MAX_DOMAIN_ID}], got {text[:40]!r}"
        ) from None
    return check_domain_id(value, "ROS_DOMAIN_ID")


#: Lock files of the domain ids this process has leased (held until the process ends).
_LEASES: list[object] = []


def lease_domain_id(first: int = 100, last: int = 199) -> int:
    """A DDS domain id in [first, last] that no other process on this machine has leased (an
    exclusive lock on a file in the temporary folder, held until this process ends): rehearsals
    and tests running side by side never share a domain."""
    import fcntl
    import tempfile

    folder = Path(tempfile.gettempdir())
    for domain_id in range(first, last + 1):
        handle = (folder / f"husky-sim-dds-domain-{domain_id}.lock").open("a")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _LEASES.append(handle)
        return domain_id
    raise RuntimeError(f"no free DDS domain id in [{first}, {last}]: every one is leased on this machine")


def check_domain_id(value: int, name: str = "domain_id") -> int:
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise ValueError(f"{name}: expected an integer in [0, {MAX_DOMAIN_ID}], got {value}")
    return value


@dataclass(frozen=True)
class Ros2Settings:
    """Topic names, frame ids and clock of the node and the rehearsal robot (ROS 2's defaults and
    Clearpath's Husky topics); `domain_id` None means ROS_DOMAIN_ID (0 when unset)."""

    odometry_topic: str = "/odometry/filtered"  # nav_msgs/Odometry in, sensor-data QoS
    cmd_vel_topic: str = "/cmd_vel"  # geometry_msgs/Twist out, every tau
    goal_topic: str = "/goal_pose"  # geometry_msgs/PoseStamped in (RViz and Nav2)
    obstacles_topic: str = "/obstacles"  # visualization_msgs/MarkerArray of cylinders in
    plan_topic: str = "/plan"  # nav_msgs/Path out (Nav2's name)
    clock_topic: str = "/clock"  # rosgraph_msgs/Clock, read only with use_sim_time
    # each topic's QoS profile (QOS_PROFILE_NAMES, made in transport.QOS_PROFILES); both ends of
    # a topic must offer what the other asks
    odometry_qos: str = "sensor_data"
    cmd_vel_qos: str = "default"
    goal_qos: str = "default"
    obstacles_qos: str = "default"
    plan_qos: str = "default"
    clock_qos: str = "clock"
    odom_frame: str = "odom"  # frame of poses, obstacles and plans
    base_frame: str = "base_link"  # odometry's child frame
    use_sim_time: bool = False  # the node's clock is /clock (a simulator) instead of the wall clock
    cmd_vel_stamped: bool = False  # geometry_msgs/TwistStamped on cmd_vel (Jazzy's diff-drive)
    node_name: str = "husky_sim_controller"  # the node's name in the ROS graph
    # the distribution whose graph layout and message definitions the Cyclone DDS transport speaks;
    # None: the graph layout of the peers, Humble's message definitions (the same on the wire)
    ros_distro: str | None = None
    domain_id: int | None = None
    localhost_only: bool = False  # keep DDS traffic on 127.0.0.1 (rehearsals)

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name.endswith("_topic"):
                topic = getattr(self, f.name)
                if not re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", topic):
                    raise ValueError(
                        f"{f.name}: expected an absolute ROS 2 topic name like /cmd_vel, got {topic[:40]!r}"
                    )
            profile = getattr(self, f.name)
            if f.name.endswith("_qos") and profile not in QOS_PROFILE_NAMES:
                raise ValueError(
                    f"{f.name}: expected one of {', '.join(QOS_PROFILE_NAMES)}, got {str(profile)[:40]!r}"
                )
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", self.node_name):
            raise ValueError(
                "node_name: expected a ROS 2 node name like husky_sim_controller, "
                f"got {self.node_name[:40]!r}"
            )
        if self.ros_distro is not None and self.ros_distro not in ROS_DISTRO_NAMES:
            raise ValueError(
                f"ros_distro: expected one of {', '.join(ROS_DISTRO_NAMES)}, "
                f"got {str(self.ros_distro)[:40]!r}"
            )
        if self.domain_id is not None:
            check_domain_id(self.domain_id)

    def resolved_domain_id(self) -> int:
        return domain_id_from_env() if self.domain_id is None else self.domain_id
