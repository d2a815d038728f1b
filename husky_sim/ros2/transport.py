"""DDS transport with ROS 2's conventions: topic names, QoS profiles, participants.

A ROS 2 topic `/cmd_vel` is the DDS topic `rt/cmd_vel` (rmw_cyclonedds_cpp's mapping); samples are
plain CDR (XCDR1), as ROS 2's Cyclone RMW writes them. The QoS profiles are ROS 2's:
`sensor_data` (best effort, keep last 5) for odometry, the default (reliable, keep last 10) for
commands, goals, plans and obstacles, and the clock's (best effort, keep last 1).
"""

from __future__ import annotations

from typing import Any

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from husky_sim.ros2.messages import message_type
from husky_sim.ros2.settings import QOS_PROFILE_NAMES, Ros2Settings

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
QOS_PROFILES: dict[str, Qos] = dict(
    zip(QOS_PROFILE_NAMES, (SENSOR_DATA_QOS, DEFAULT_QOS, CLOCK_QOS), strict=True)
)

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


def topic_qos(settings: Ros2Settings, topic: str) -> Qos:
    """The QoS of a topic by its setting's stem: `topic_qos(s, "odometry")` -> sensor data by default."""
    return QOS_PROFILES[getattr(settings, f"{topic}_qos")]


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
    samples = take_all(reader)
    return samples[-1] if samples else None


def take_all(reader: DataReader) -> list[Any]:
    """Every valid sample waiting on a reader, oldest first."""
    return [
        s for s in reader.take(N=256) if getattr(s, "sample_info", None) is None or s.sample_info.valid_data
    ]
