"""ROS 2 message types for Cyclone DDS, built from ROS 2's published message definitions.

The field layouts come from the ROS 2 message definitions that `rosbags` ships (its
`ros2_humble` type store: Clearpath's Husky A200 stack runs Humble), never from a hand-written
copy; each becomes a Cyclone DDS `IdlStruct` under the name `rmw_cyclonedds_cpp` gives it on the
wire (`geometry_msgs::msg::dds_::Twist_`), `@final` and serialised as plain CDR (XCDR1), which is
what ROS 2's Cyclone RMW writes and reads. Cyclone DDS does the serialising.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
from typing import Any

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import annotations as idl_annotations
from cyclonedds.idl import types as idl

#: The ROS 2 distribution whose message definitions are used (rosbags.typesys.Stores member).
ROS_DISTRO = "ROS2_HUMBLE"

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
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(getattr(Stores, ROS_DISTRO))


def dds_type_name(ros_type: str) -> str:
    """`geometry_msgs/msg/Twist` -> `geometry_msgs::msg::dds_::Twist_` (rmw_cyclonedds_cpp's name)."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def _default_for(spec: tuple) -> Any:
    """A default-value factory for one field, so messages can be built field by field."""
    node, arg = spec
    kind = node.name
    if kind == "BASE":
        base = arg[0]
        return {"bool": lambda: False, "string": lambda: ""}.get(
            base, (lambda: 0.0) if base.startswith("float") else (lambda: 0)
        )
    if kind == "NAME":
        return message_type(arg)
    if kind == "ARRAY":
        (inner_node, inner_arg), length = arg
        inner = _default_for((inner_node, inner_arg))
        return lambda: [inner() for _ in range(length)]
    return list  # SEQUENCE: empty


def _annotation(spec: tuple) -> Any:
    node, arg = spec
    kind = node.name
    if kind == "BASE":
        base, bound = arg
        if base == "string" and bound:
            return idl.bounded_str[bound]
        return _PRIMITIVES[base]
    if kind == "NAME":
        return message_type(arg)
    (inner_spec, length) = arg
    inner = _annotation(inner_spec)
    if kind == "ARRAY":
        return idl.array[inner, length]
    return idl.sequence[inner, length] if length else idl.sequence[inner]


@functools.cache
def message_type(ros_type: str) -> type:
    """The Cyclone DDS type of a ROS 2 message, e.g. `message_type("geometry_msgs/msg/Twist")`.

    Fields have ROS 2's defaults (zeros, empty strings and sequences, default sub-messages).
    """
    try:
        _constants, fields = _typestore().fielddefs[ros_type]
    except KeyError:
        raise ValueError(f"message type: {ros_type!r} is not a ROS 2 message type") from None
    annotations = {name: _annotation(spec) for name, spec in fields}
    namespace = {
        "__annotations__": annotations,
        "__module__": __name__,
        "__qualname__": ros_type.split("/")[-1],
    }
    for name, spec in fields:
        namespace[name] = dataclasses.field(default_factory=_default_for(spec))
    cls = types.new_class(
        ros_type.split("/")[-1],
        (IdlStruct,),
        {"typename": dds_type_name(ros_type)},
        lambda ns: ns.update(namespace),
    )
    return dataclasses.dataclass(idl_annotations.final(cls))  # @final: plain CDR, as ROS 2 writes


# The messages the node and the rehearsal robot exchange (ROS 2 type names).
TWIST = "geometry_msgs/msg/Twist"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
MARKER = "visualization_msgs/msg/Marker"
PATH = "nav_msgs/msg/Path"
CLOCK = "rosgraph_msgs/msg/Clock"

#: visualization_msgs/Marker constants (from the same definitions).
MARKER_CYLINDER = 3
MARKER_ADD = 0
MARKER_DELETEALL = 3


def make(ros_type: str, **fields: Any) -> Any:
    """A message of a ROS 2 type with the given fields (others at their defaults)."""
    return message_type(ros_type)(**fields)


def to_time(t_s: float) -> Any:
    """builtin_interfaces/Time of t_s seconds (rounded to the nanosecond)."""
    total = round(t_s * 1e9)
    sec, nanosec = divmod(total, 1_000_000_000)
    return make("builtin_interfaces/msg/Time", sec=int(sec), nanosec=int(nanosec))


def from_time(stamp: Any) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return stamp.sec + 1e-9 * stamp.nanosec


def yaw_quaternion(yaw_rad: float) -> Any:
    """geometry_msgs/Quaternion of a rotation by yaw_rad about z."""
    return make(
        "geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2)
    )


def quaternion_yaw(q: Any) -> float:
    """Yaw (rad) of a geometry_msgs/Quaternion (rotation about z of its heading)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose(x_m: float, y_m: float, yaw_rad: float) -> Any:
    """geometry_msgs/Pose in the plane."""
    return make(
        "geometry_msgs/msg/Pose",
        position=make("geometry_msgs/msg/Point", x=float(x_m), y=float(y_m), z=0.0),
        orientation=yaw_quaternion(float(yaw_rad)),
    )


def header(t_s: float, frame_id: str) -> Any:
    return make("std_msgs/msg/Header", stamp=to_time(t_s), frame_id=frame_id)
