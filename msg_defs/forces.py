"""Force commands in the formats of FORCE_OUTPUT_FORMATS, and the tool wrench as WrenchStamped or its CDR
bytes, and back."""
from __future__ import annotations

import array

import numpy as np
from geometry_msgs.msg import Vector3, Wrench, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from liver_sim.base.topic_names import FORCE_OUTPUT_FORMATS
from msg_defs import cdr
from msg_defs.finite import finite_array, finite_floats
from msg_defs.stamps import header_msg, stamp_parts

_FORCE_TYPES = {"wrench_stamped": WrenchStamped, "wrench": Wrench, "vector3": Vector3,
                "float64_array": Float64MultiArray}


def _vector3_msg(value, name: str) -> Vector3:
    x, y, z = finite_array(value, (3,), name).tolist()
    return Vector3(x=x, y=y, z=z)


def wrench_stamped(force, stamp, frame_id: str, torque=(0.0, 0.0, 0.0)) -> WrenchStamped:
    """WrenchStamped of a force (N) and torque (N·m)."""
    return WrenchStamped(header=header_msg(stamp, frame_id),
                         wrench=Wrench(force=_vector3_msg(force, "force"), torque=_vector3_msg(torque, "torque")))


def wrench_stamped_bytes(force, stamp, frame_id: str) -> bytes:
    """Serialized :func:`wrench_stamped` with zero torque, without a message object."""
    fx, fy, fz = finite_floats(tuple(map(float, force)), (3,), "force")
    return cdr.encode(*stamp_parts(stamp), frame_id, (fx, fy, fz, 0.0, 0.0, 0.0))


def force_message_type(fmt: str) -> type:
    """Message class of the force output format `fmt` (one of FORCE_OUTPUT_FORMATS).

    'omni_feedback' is omni_msgs/OmniFeedback from the user's Geomagic Touch driver workspace, imported
    here; ValueError when that workspace is not sourced or `fmt` is unknown.
    """
    if fmt == "omni_feedback":
        try:
            from omni_msgs.msg import OmniFeedback  # optional: the user's Geomagic Touch driver workspace
        except ImportError as exc:
            raise ValueError("force_output 'omni_feedback' needs omni_msgs (Geomagic Touch ROS 2 driver workspace) "
                             "sourced; it is not installed") from exc
        return OmniFeedback
    if fmt not in _FORCE_TYPES:
        raise ValueError(f"force_output must be one of {FORCE_OUTPUT_FORMATS}, got {fmt!r}")
    return _FORCE_TYPES[fmt]


def force_message(fmt: str, force, stamp, frame_id: str):
    """The force command (N) in format `fmt`: WrenchStamped (torque 0, stamp, frame_id), Wrench (torque 0),
    Vector3, Float64MultiArray data [fx, fy, fz], or OmniFeedback.force (its lock `position` left 0)."""
    msg_type = force_message_type(fmt)
    if fmt == "wrench_stamped":
        return wrench_stamped(force, stamp, frame_id)
    vector = _vector3_msg(force, "force")
    if fmt == "wrench":
        return Wrench(force=vector)
    if fmt == "vector3":
        return vector
    if fmt == "float64_array":
        return Float64MultiArray(data=array.array("d", (vector.x, vector.y, vector.z)))
    return msg_type(force=vector)


def force_message_bytes(fmt: str, force, stamp, frame_id: str) -> bytes:
    """Serialized :func:`force_message`: WrenchStamped without a message object, other formats via rclpy."""
    if fmt == "wrench_stamped":
        return wrench_stamped_bytes(force, stamp, frame_id)

    return serialize_message(force_message(fmt, force, stamp, frame_id))


#: The longest serialized force command (bytes) of a format other than wrench_stamped read by a loop: a
#: Float64MultiArray of 3 values with a short layout, or a Wrench, Vector3 or OmniFeedback.
MAX_FORCE_COMMAND_BYTES = 1024


def stamped_force_from_bytes(data: bytes) -> tuple[np.ndarray, tuple[int, int]]:
    """(force (3,) N, stamp (sec, nanosec)) of a serialized WrenchStamped, decoded directly; refuses malformed or
    oversized bytes (msg_defs.cdr.MAX_BYTES) and non-finite values, naming the field."""
    sec, nanosec, _, values = cdr.decode(data, cdr.WRENCH_FIELDS, "WrenchStamped")
    return np.array(finite_floats(values[:3], (3,), "WrenchStamped force")), (sec, nanosec)


def force_from_bytes(fmt: str, data: bytes) -> np.ndarray:
    """:func:`force_from_message` of a serialized force command: WrenchStamped decoded directly, the other
    formats deserialized once their length is checked (MAX_FORCE_COMMAND_BYTES)."""
    if fmt == "wrench_stamped":
        return stamped_force_from_bytes(data)[0]
    if len(data) > MAX_FORCE_COMMAND_BYTES:
        raise ValueError(f"force command ({fmt}): {len(data)} bytes, more than {MAX_FORCE_COMMAND_BYTES}")
    return force_from_message(fmt, deserialize_message(data, force_message_type(fmt)))


def force_from_message(fmt: str, msg) -> np.ndarray:
    """The (3,) force (N) carried by a force output message of format `fmt`; refuses a message of the
    wrong type, a Float64MultiArray without exactly 3 values, and non-finite values."""
    msg_type = force_message_type(fmt)
    if not isinstance(msg, msg_type):
        raise ValueError(f"force_output {fmt!r} carries {msg_type.__name__}, got {type(msg).__name__}")
    if fmt == "float64_array":
        if len(msg.data) != 3:
            raise ValueError(f"Float64MultiArray.data has {len(msg.data)} values, expected 3 (fx, fy, fz)")
        return finite_array(msg.data, (3,), "Float64MultiArray.data")
    if fmt == "wrench_stamped":
        vector = msg.wrench.force
    elif fmt == "vector3":
        vector = msg
    else:
        vector = msg.force
    return finite_array((vector.x, vector.y, vector.z), (3,), f"{msg_type.__name__} force")
