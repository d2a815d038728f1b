"""ROS 2 messages: Cyclone DDS types built from ROS 2's published message definitions, and the
helpers that build a message of either family (those Cyclone DDS types or rclpy's classes).

The field layouts come from the ROS 2 message definitions that `rosbags` ships (a distribution's
type store: Humble by default, which Clearpath's Husky A200 stack runs), never from a hand-written
copy; each becomes a Cyclone DDS `IdlStruct` under the name ROS 2's middlewares give it on the
wire (`geometry_msgs::msg::dds_::Twist_`), `@final` and serialised as plain CDR (XCDR1), which is
what ROS 2 writes and reads. Cyclone DDS does the serialising.

Of the messages the node exchanges, Humble's and the newer distributions' definitions (Jazzy,
Kilted: the `ros-rclpy` wheels') differ on the wire only in the graph's `rmw_dds_common/Gid`
(24 bytes in Humble, 16 since Jazzy); `visualization_msgs/Marker` gained a constant
(ARROW_STRIP), which is not on the wire. tests/ros2/test_rclpy.py checks this against the wheels.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
from collections.abc import Callable
from typing import Any

from husky_sim.extras import missing, require
from husky_sim.ros2.settings import ROS_DISTRO_NAMES

try:
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl import annotations as idl_annotations
    from cyclonedds.idl import types as idl
except ImportError:  # the core install has no DDS binding
    raise missing("cyclonedds", "ros2", "ROS 2's messages (serve, rehearse)") from None

#: Each distribution's rosbags.typesys.Stores member; the first is the default (Humble:
#: Clearpath's A200 stack).
ROS_DISTROS = {name: f"ROS2_{name.upper()}" for name in ROS_DISTRO_NAMES}
DEFAULT_DISTRO = ROS_DISTRO_NAMES[0]

_PRIMITIVES: dict[str, Any] = {
    "bool": bool,
    "byte": idl.byte,
    "char": idl.uint8,  # ROS 2 `char` is an unsigned 8-bit integer on the wire
    "int8": idl.int8,
    "uint8": idl.uint8,
    "int16": idl.int16,
    "uint16": idl.uint16,
    "int32": idl.int32,
    "uint32": idl.uint32,
    "int64": idl.int64,
    "uint64": idl.uint64,
    "float32": idl.float32,
    "float64": idl.float64,
    "string": str,
}


@functools.cache
def _typestore(distro: str):
    Stores, get_typestore = (
        getattr(require("rosbags.typesys", "ros2", "ROS 2's message types"), name)
        for name in ("Stores", "get_typestore")
    )

    return get_typestore(getattr(Stores, ROS_DISTROS[distro]))


def dds_type_name(ros_type: str) -> str:
    """`geometry_msgs/msg/Twist` -> `geometry_msgs::msg::dds_::Twist_` (rmw_cyclonedds_cpp's name)."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def _default_for(spec: tuple, distro: str) -> Any:
    """A default-value factory for one field, so messages can be built field by field."""
    node, arg = spec
    kind = node.name
    if kind == "BASE":
        base = arg[0]
        return {"bool": lambda: False, "string": lambda: ""}.get(
            base, (lambda: 0.0) if base.startswith("float") else (lambda: 0)
        )
    if kind == "NAME":
        return message_type(arg, distro)
    if kind == "ARRAY":
        (inner_node, inner_arg), length = arg
        inner = _default_for((inner_node, inner_arg), distro)
        return lambda: [inner() for _ in range(length)]
    return list  # SEQUENCE: empty


def _annotation(spec: tuple, distro: str) -> Any:
    node, arg = spec
    kind = node.name
    if kind == "BASE":
        base, bound = arg
        if base == "string" and bound:
            return idl.bounded_str[bound]
        return _PRIMITIVES[base]
    if kind == "NAME":
        return message_type(arg, distro)
    (inner_spec, length) = arg
    inner = _annotation(inner_spec, distro)
    if kind == "ARRAY":
        return idl.array[inner, length]
    return idl.sequence[inner, length] if length else idl.sequence[inner]


def message_type(ros_type: str, distro: str = DEFAULT_DISTRO) -> type:
    """The Cyclone DDS type of a ROS 2 message in a distribution's definition, e.g.
    `message_type("geometry_msgs/msg/Twist")`: one class per type and distribution.

    Fields have ROS 2's defaults (zeros, empty strings and sequences, default sub-messages).
    """
    return _message_type(ros_type, distro)


@functools.cache
def _message_type(ros_type: str, distro: str) -> type:
    try:
        _constants, fields = _typestore(distro).fielddefs[ros_type]
    except KeyError:
        raise ValueError(f"message type: {ros_type!r} is not a ROS 2 message type") from None
    annotations = {name: _annotation(spec, distro) for name, spec in fields}
    namespace = {
        "__annotations__": annotations,
        "__module__": __name__,
        "__qualname__": ros_type.split("/")[-1],
    }
    for name, spec in fields:
        namespace[name] = dataclasses.field(default_factory=_default_for(spec, distro))
    cls = types.new_class(
        ros_type.split("/")[-1],
        (IdlStruct,),
        {"typename": dds_type_name(ros_type)},
        lambda ns: ns.update(namespace),
    )
    return dataclasses.dataclass(idl_annotations.final(cls))  # @final: plain CDR, as ROS 2 writes


# The messages the node and the rehearsal robot exchange (ROS 2 type names).
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"  # Jazzy's diff-drive controllers take this
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
MARKER = "visualization_msgs/msg/Marker"
PATH = "nav_msgs/msg/Path"
CLOCK = "rosgraph_msgs/msg/Clock"
PARTICIPANT_ENTITIES_INFO = "rmw_dds_common/msg/ParticipantEntitiesInfo"  # the ROS graph

#: visualization_msgs/Marker constants (from the same definitions).
MARKER_CYLINDER = 3
MARKER_ADD = 0
MARKER_DELETEALL = 3


def from_time(stamp: Any) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return stamp.sec + 1e-9 * stamp.nanosec


def quaternion_yaw(q: Any) -> float:
    """Yaw (rad) of a geometry_msgs/Quaternion (rotation about z of its heading)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


@dataclasses.dataclass(frozen=True)
class MessageKit:
    """Builds ROS 2 messages of one family: `type_of("nav_msgs/msg/Odometry")` gives its class
    (our Cyclone DDS types, or rclpy's generated ones: the same fields either way)."""

    type_of: Callable[[str], type]

    def make(self, ros_type: str, **fields: Any) -> Any:
        """A message of a ROS 2 type with the given fields (others at their defaults)."""
        return self.type_of(ros_type)(**fields)

    def to_time(self, t_s: float) -> Any:
        """builtin_interfaces/Time of t_s seconds (rounded to the nanosecond)."""
        sec, nanosec = divmod(round(t_s * 1e9), 1_000_000_000)
        return self.make("builtin_interfaces/msg/Time", sec=int(sec), nanosec=int(nanosec))

    def yaw_quaternion(self, yaw_rad: float) -> Any:
        """geometry_msgs/Quaternion of a rotation by yaw_rad about z."""
        return self.make(
            "geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2)
        )

    def pose(self, x_m: float, y_m: float, yaw_rad: float) -> Any:
        """geometry_msgs/Pose in the plane."""
        return self.make(
            "geometry_msgs/msg/Pose",
            position=self.make("geometry_msgs/msg/Point", x=float(x_m), y=float(y_m), z=0.0),
            orientation=self.yaw_quaternion(float(yaw_rad)),
        )

    def header(self, t_s: float, frame_id: str) -> Any:
        """std_msgs/Header stamped t_s (s) in frame_id."""
        return self.make("std_msgs/msg/Header", stamp=self.to_time(t_s), frame_id=frame_id)


def cyclone_kit(distro: str = DEFAULT_DISTRO) -> MessageKit:
    """The kit of our Cyclone DDS types in a distribution's definitions."""
    return MessageKit(functools.partial(message_type, distro=distro))


#: The default distribution's kit, for code and tests that build messages without a transport.
DEFAULT_KIT = cyclone_kit()
make, to_time, yaw_quaternion, pose, header = (
    DEFAULT_KIT.make,
    DEFAULT_KIT.to_time,
    DEFAULT_KIT.yaw_quaternion,
    DEFAULT_KIT.pose,
    DEFAULT_KIT.header,
)
