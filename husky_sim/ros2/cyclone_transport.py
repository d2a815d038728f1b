"""The Cyclone DDS transport: ROS 2's wire conventions from Python, with no ROS install.

A ROS 2 topic `/cmd_vel` is the DDS topic `rt/cmd_vel`; samples are plain CDR (XCDR1), as ROS 2
writes them. The QoS profiles are ROS 2's: `sensor_data` (best effort, keep last 5) for odometry,
the default (reliable, keep last 10) for commands, goals, plans and obstacles, and the clock's
(best effort, keep last 1).

Two things make a ROS 2 node of it, as rmw does for its nodes:
- **Type matching by name, for Fast DDS's endpoints.** Fast DDS (ROS 2's default middleware)
  announces XTypes type information whose collection element flags leave "try construct" unset,
  which the XTypes specification leaves undefined; Cyclone DDS rejects that type object, so for
  every type with a sequence or an array (Odometry, Path, MarkerArray) the type hashes differ,
  Cyclone cannot resolve Fast DDS's type and the endpoints never match. Cyclone's
  `Compatibility/IgnoreTypeInformation` for eProsima's vendor id (1.15) matches those endpoints
  by type name instead, as ROS 2's own Cyclone middleware does (it announces no type
  information). Our types are ROS 2's definitions, checked byte for byte against ROS 2's
  serializers (tests/ros2), so a name match is a type match.
- **The ROS graph.** A ROS 2 node is what its participant announces on `ros_discovery_info`
  (rmw_dds_common/ParticipantEntitiesInfo: the participant's gid, and per node its name and the
  gids of its readers and writers); the transport announces its node there each time it adds a
  reader or writer, so `ros2 node list` and rclpy's graph queries list it with its topics.

The graph's gid is 24 bytes in Humble and 16 from Iron on (Jazzy, Kilted), and a peer reads only
its own distribution's layout. Unless a distribution is given (`ros_distro`), the transport
follows its peers: it announces in Humble's layout (which a newer peer reads as the same
participant with no node, while the reverse would give a Humble peer a garbled one), and from the
first peer's `ros_discovery_info` writer it sees in discovery data (DCPSPublication) on, in that
peer's: from Iron on, ROS 2's endpoints carry `typehash=` (REP 2011's type hashes) in their user
data; Humble's carry none. The messages of the node's own topics are the same on the wire in every
distribution (tests/ros2/test_rclpy.py). ROS 2 does not support mixed distributions on one domain:
the first peer decides, and a later peer of another layout is named in one line on stderr.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
from typing import Any

from husky_sim.extras import missing
from husky_sim.ros2 import messages as msg
from husky_sim.ros2.dds_config import URI_VARIABLE, DdsConfigError, merged_config, refusal
from husky_sim.ros2.settings import QOS_PROFILE_NAMES, Ros2Settings
from husky_sim.ros2.transport import Received, TopicsBySetting

try:
    from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
    from cyclonedds.core import (
        DDSException,
        InstanceState,
        Policy,
        Qos,
        ReadCondition,
        SampleState,
        ViewState,
        WaitSet,
    )
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration
except ImportError:  # the core install has no DDS binding
    raise missing("cyclonedds", "ros2", "the Cyclone DDS transport (serve, rehearse)") from None

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
#: rmw's QoS of ros_discovery_info: a late joiner gets each participant's last announcement.
GRAPH_QOS = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.History.KeepLast(1),
    Policy.Durability.TransientLocal,
    _XCDR1,
)
GRAPH_TOPIC = "ros_discovery_info"
#: A ROS 2 participant's user data: its security enclave (the root one).
PARTICIPANT_USER_DATA = b"enclave=/;"
#: What a ROS 2 endpoint's user data holds from Iron on (REP 2011), and Humble's never.
TYPE_HASH_USER_DATA = b"typehash="
#: The graph's layouts: Humble's 24-byte gids and the 16-byte ones of every later distribution.
HUMBLE_GRAPH, LATER_GRAPH = "humble", "kilted"


def graph_layout(user_data: bytes | None) -> str:
    """The graph layout of a ROS 2 peer, from the user data of its ros_discovery_info writer."""
    return LATER_GRAPH if user_data and TYPE_HASH_USER_DATA in user_data else HUMBLE_GRAPH


def topic_qos(settings: Ros2Settings, topic: str) -> Qos:
    """The QoS of a topic by its setting's stem: `topic_qos(s, "odometry")` -> sensor data by default."""
    return QOS_PROFILES[getattr(settings, f"{topic}_qos")]


def dds_topic_name(ros_topic: str) -> str:
    """`/cmd_vel` -> `rt/cmd_vel` (ROS 2 topics on DDS)."""
    return "rt" + ros_topic


def open_domain(domain_id: int, localhost_only: bool) -> Domain:
    """Configure a DDS domain for this process (husky_sim.ros2.dds_config: the user's
    CYCLONEDDS_URI, then ours). Cyclone DDS's own diagnostics, which it writes to the process's
    stderr (file descriptor 2, redirected while the domain is created and always restored), become
    a one-line DdsConfigError when it refuses the configuration; a notice names what was set aside."""
    merged = merged_config(localhost_only)
    sys.stderr.flush()
    error: DDSException | None = None
    with tempfile.TemporaryFile() as log:
        saved = os.dup(2)
        try:
            os.dup2(log.fileno(), 2)
            domain = Domain(domain_id, merged.xml)
        except DDSException as exc:
            error = exc
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        log.seek(0)
        said = log.read().decode(errors="replace")
    if error is not None:
        raise DdsConfigError(
            f"{URI_VARIABLE}: Cyclone DDS refused the configuration ({refusal(said)}); "
            f"fix it or unset {URI_VARIABLE}"
        ) from None
    if said:
        sys.stderr.write(said)
    if merged.notice():
        print(merged.notice(), file=sys.stderr, flush=True)
    return domain


#: Domains this process configured, by id (one configuration per id and process, kept for the
#: process's life: the first transport on a domain decides whether it is localhost-only), and the
#: lock that makes configuring one (and redirecting stderr for it) one thread's at a time.
_CONFIGURED_DOMAINS: dict[int, Domain] = {}
_CONFIGURING = threading.Lock()


class _Subscription:
    def __init__(self, reader: DataReader) -> None:
        self.reader = reader

    def take(self) -> list[Received]:
        samples = self.reader.take(N=256)
        return [
            Received(s, s.sample_info.source_timestamp)
            for s in samples
            if getattr(s, "sample_info", None) is not None and s.sample_info.valid_data
        ]

    def publishers(self) -> int:
        return len(self.reader.get_matched_publications())


class _Publisher:
    def __init__(self, writer: DataWriter) -> None:
        self.writer = writer

    def write(self, message: Any) -> None:
        self.writer.write(message)

    def subscribers(self) -> int:
        return len(self.writer.get_matched_subscriptions())

    def wait_for_acks(self, timeout_s: float) -> bool:
        return bool(self.writer.wait_for_acks(duration(seconds=timeout_s)))


class CycloneTransport(TopicsBySetting):
    """One DDS participant: one ROS 2 node's topics, announced in the ROS graph."""

    def __init__(self, settings: Ros2Settings) -> None:
        self.settings = settings
        self.messages = msg.cyclone_kit(settings.ros_distro or msg.DEFAULT_DISTRO)
        domain_id = settings.resolved_domain_id()
        with _CONFIGURING:
            if domain_id not in _CONFIGURED_DOMAINS:
                _CONFIGURED_DOMAINS[domain_id] = open_domain(domain_id, settings.localhost_only)
        self.participant = DomainParticipant(domain_id, qos=Qos(Policy.Userdata(PARTICIPANT_USER_DATA)))
        self._topics: dict[str, Topic] = {}
        self._readers: list[DataReader] = []
        self._writers: list[DataWriter] = []
        self._waitset = WaitSet(self.participant)
        #: The graph layout announced in (a distribution's name); None until a peer decides it.
        self.graph_distro = settings.ros_distro
        self._publications = (
            BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
            if settings.ros_distro is None
            else None
        )
        self._mixed_reported = False
        self._open_graph(settings.ros_distro or HUMBLE_GRAPH)

    def _topic(self, ros_topic: str, ros_type: str) -> Topic:
        if ros_topic not in self._topics:
            self._topics[ros_topic] = Topic(
                self.participant,
                dds_topic_name(ros_topic),
                msg.message_type(ros_type, self.settings.ros_distro or msg.DEFAULT_DISTRO),
            )
        return self._topics[ros_topic]

    def subscribe_topic(self, ros_topic: str, ros_type: str, qos: str) -> _Subscription:
        reader = DataReader(self.participant, self._topic(ros_topic, ros_type), qos=QOS_PROFILES[qos])
        self._waitset.attach(ReadCondition(reader, SampleState.NotRead | ViewState.Any | InstanceState.Any))
        self._readers.append(reader)
        self._announce()
        return _Subscription(reader)

    def publish_topic(self, ros_topic: str, ros_type: str, qos: str) -> _Publisher:
        writer = DataWriter(self.participant, self._topic(ros_topic, ros_type), qos=QOS_PROFILES[qos])
        self._writers.append(writer)
        self._announce()
        return _Publisher(writer)

    def wait(self, timeout_s: float) -> None:
        self._waitset.wait(duration(milliseconds=max(1, round(1000 * timeout_s))))
        self._follow_peers()

    def close(self) -> None:
        """Nothing to release by hand: Cyclone DDS deletes the entities with their Python objects."""

    # -- the ROS graph ---------------------------------------------------------------------------
    def _open_graph(self, layout: str) -> None:
        """The ros_discovery_info writer in a layout (a distribution's name), replacing any other."""
        self._graph_kit = msg.cyclone_kit(layout)
        graph_type = msg.message_type(msg.PARTICIPANT_ENTITIES_INFO, layout)
        self._graph = DataWriter(
            self.participant, Topic(self.participant, GRAPH_TOPIC, graph_type), qos=GRAPH_QOS
        )

    def _follow_peers(self) -> None:
        """Take the discovery data of peers' ros_discovery_info writers: the first decides the
        layout this node is announced in (re-announced at once when it differs)."""
        if self._publications is None:
            return
        for sample in self._publications.take(N=64):
            if (
                getattr(sample, "topic_name", None) != GRAPH_TOPIC
                or sample.participant_key == self.participant.guid
            ):
                continue
            user_data = sample.qos[Policy.Userdata] if sample.qos else None
            layout = graph_layout(user_data.data if user_data else None)
            if self.graph_distro is None:  # announced in Humble's layout until now
                self.graph_distro = layout
                if layout != HUMBLE_GRAPH:
                    self._open_graph(layout)
                    self._announce()
            elif layout != self.graph_distro and not self._mixed_reported:
                self._mixed_reported = True
                print(
                    "ROS graph: peers of both layouts on one domain (Humble's 24-byte gids and later "
                    "ones' 16); this node stays announced in the first peer's; --ros-distro chooses",
                    file=sys.stderr,
                    flush=True,
                )

    def _gid(self, entity: Any) -> Any:
        """rmw_dds_common/Gid of a DDS entity: its GUID's 16 bytes (zero-padded to Humble's 24)."""
        gid = self._graph_kit.make("rmw_dds_common/msg/Gid")
        raw = list(entity.guid.bytes)
        gid.data = raw + [0] * (len(gid.data) - len(raw))
        return gid

    def _announce(self) -> None:
        """Publish this participant's one node, its readers and writers, on ros_discovery_info."""
        kit = self._graph_kit
        node = kit.make(
            "rmw_dds_common/msg/NodeEntitiesInfo",
            node_namespace="/",
            node_name=self.settings.node_name,
            reader_gid_seq=[self._gid(r) for r in self._readers],
            writer_gid_seq=[self._gid(w) for w in self._writers],
        )
        self._graph.write(
            kit.make(
                msg.PARTICIPANT_ENTITIES_INFO, gid=self._gid(self.participant), node_entities_info_seq=[node]
            )
        )
