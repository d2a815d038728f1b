"""DDS transport with ROS 2's conventions: topic names, QoS profiles, domain id, settings.

A ROS 2 topic `/cmd_vel` is the DDS topic `rt/cmd_vel` (rmw_cyclonedds_cpp's mapping); samples are
plain CDR (XCDR1), as ROS 2's Cyclone RMW writes them. The QoS profiles are ROS 2's:
`sensor_data` (best effort, keep last 5) for odometry, the default (reliable, keep last 10) for
commands, goals, plans and obstacles, and the clock's (best effort, keep last 1).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from husky_sim.ros2.messages import message_type

#: DDS domain ids Cyclone DDS can map to ports (ROS 2 recommends 0 to 101 on Linux).
MAX_DOMAIN_ID = 232

_XCDR1 = Policy.DataRepresentation(use_cdrv0_representation=True)

SENSOR_DATA_QOS = Qos(
    Policy.Reliability.BestEffort,
    Policy.History.KeepLast(5),
    Policy.Durability.Volatile,
    _XCDR1,
)
DEFAULT_QOS = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.History.KeepLast(10),
    Policy.Durability.Volatile,
    _XCDR1,
)
CLOCK_QOS = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1), Policy.Durability.Volatile, _XCDR1)
#: The profiles a topic's QoS setting may name (ROS 2's names).
QOS_PROFILES: dict[str, Qos] = {"sensor_data": SENSOR_DATA_QOS, "default": DEFAULT_QOS, "clock": CLOCK_QOS}

#: Cyclone DDS configuration that keeps all traffic on this machine's loopback interface: no
#: multicast, discovery by unicast to 127.0.0.1. A rehearsal uses it so its /cmd_vel can never
#: reach a robot on the network. Reliable writers send heartbeats every 5 ms instead of 100 ms,
#: so a write is acknowledged within about a millisecond: the rehearsal robot waits for the
#: node's acknowledgement of the obstacles each step, which took 74 ms (median) at the default.
LOCALHOST_ONLY_CONFIG = """<CycloneDDS><Domain id="any">
<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>
<AllowMulticast>false</AllowMulticast></General>
<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
<Peers><Peer address="127.0.0.1"/></Peers></Discovery>
<Internal><HeartbeatInterval min="1 ms" minsched="1 ms">5 ms</HeartbeatInterval></Internal>
</Domain></CycloneDDS>"""


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
    # each topic's QoS profile (QOS_PROFILES); both ends of a topic must offer what the other asks
    odometry_qos: str = "sensor_data"
    cmd_vel_qos: str = "default"
    goal_qos: str = "default"
    obstacles_qos: str = "default"
    plan_qos: str = "default"
    clock_qos: str = "clock"
    odom_frame: str = "odom"  # frame of poses, obstacles and plans
    base_frame: str = "base_link"  # odometry's child frame
    use_sim_time: bool = False  # the node's clock is /clock (a simulator) instead of the wall clock
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
            if f.name.endswith("_qos") and profile not in QOS_PROFILES:
                raise ValueError(
                    f"{f.name}: expected one of {', '.join(QOS_PROFILES)}, got {str(profile)[:40]!r}"
                )
        if self.domain_id is not None:
            check_domain_id(self.domain_id)

    def qos(self, topic: str) -> Qos:
        """The QoS of a topic by its setting's stem: `qos("odometry")` -> sensor data by default."""
        return QOS_PROFILES[getattr(self, f"{topic}_qos")]

    def resolved_domain_id(self) -> int:
        return domain_id_from_env() if self.domain_id is None else self.domain_id


def dds_topic_name(ros_topic: str) -> str:
    """`/cmd_vel` -> `rt/cmd_vel` (ROS 2 topics on DDS)."""
    return "rt" + ros_topic


#: Domains this process created with LOCALHOST_ONLY_CONFIG, by id.
_CONFIGURED_DOMAINS: dict[int, Domain] = {}


class Participant:
    """One DDS participant and the topics, readers and writers made from it."""

    def __init__(self, settings: Ros2Settings) -> None:
        domain_id = settings.resolved_domain_id()
        if settings.localhost_only and domain_id not in _CONFIGURED_DOMAINS:
            # one configured Domain per id and process, kept for the process's life
            _CONFIGURED_DOMAINS[domain_id] = Domain(domain_id, LOCALHOST_ONLY_CONFIG)
        self.participant = DomainParticipant(domain_id)
        self._topics: dict[str, Topic] = {}

    def _topic(self, ros_topic: str, ros_type: str) -> Topic:
        if ros_topic not in self._topics:
            self._topics[ros_topic] = Topic(
                self.participant, dds_topic_name(ros_topic), message_type(ros_type)
            )
        return self._topics[ros_topic]

    def writer(self, ros_topic: str, ros_type: str, qos: Qos = DEFAULT_QOS) -> DataWriter:
        return DataWriter(self.participant, self._topic(ros_topic, ros_type), qos=qos)

    def reader(self, ros_topic: str, ros_type: str, qos: Qos = DEFAULT_QOS) -> DataReader:
        return DataReader(self.participant, self._topic(ros_topic, ros_type), qos=qos)


def take_latest(reader: DataReader) -> Any | None:
    """The newest valid sample waiting on a reader (older ones are dropped), or None."""
    latest = None
    for sample in reader.take(N=64):
        if getattr(sample, "sample_info", None) is None or sample.sample_info.valid_data:
            latest = sample
    return latest


def take_all(reader: DataReader) -> list[Any]:
    """Every valid sample waiting on a reader, oldest first."""
    return [
        s for s in reader.take(N=256) if getattr(s, "sample_info", None) is None or s.sample_info.valid_data
    ]
