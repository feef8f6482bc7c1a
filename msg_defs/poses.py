"""Poses: a position (m) and an (x, y, z, w) quaternion as Pose, PoseStamped or its CDR bytes, and back."""
from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion

from msg_defs import cdr
from msg_defs.finite import finite_array, finite_floats, unit_quaternion
from msg_defs.stamps import header_msg, stamp_parts


def pose_msg(position, orientation_xyzw, position_name: str) -> Pose:
    x, y, z = finite_array(position, (3,), position_name).tolist()
    qx, qy, qz, qw = unit_quaternion(orientation_xyzw, "orientation_xyzw").tolist()
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def pose_arrays(pose: Pose, name: str) -> tuple[np.ndarray, np.ndarray]:
    position = finite_array((pose.position.x, pose.position.y, pose.position.z), (3,), f"{name}.position")
    o = pose.orientation
    return position, unit_quaternion((o.x, o.y, o.z, o.w), f"{name}.orientation")


def pose_stamped(position, orientation_xyzw, stamp, frame_id: str) -> PoseStamped:
    """PoseStamped of a position (m) and an (x, y, z, w) quaternion (normalised here)."""
    return PoseStamped(header=header_msg(stamp, frame_id), pose=pose_msg(position, orientation_xyzw, "position"))


def pose_to_arrays(msg_pose: Pose | PoseStamped) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,) m, unit quaternion (4,) x, y, z, w) of a Pose or PoseStamped; refuses non-finite
    values and a zero quaternion, naming the field."""
    if isinstance(msg_pose, PoseStamped):
        return pose_arrays(msg_pose.pose, "PoseStamped.pose")
    return pose_arrays(msg_pose, "Pose")


#: The identity orientation (x, y, z, w), taken as it is (no normalising) by :func:`pose_stamped_bytes`.
IDENTITY = (0.0, 0.0, 0.0, 1.0)


def pose_stamped_bytes(position, orientation_xyzw, stamp, frame_id: str) -> bytes:
    """Serialized :func:`pose_stamped` (for ``Publisher.publish(bytes)``), without a message object; a tuple
    position and the IDENTITY orientation take the 1 kHz path (no numpy)."""
    if type(position) is tuple:
        x, y, z = finite_floats(position, (3,), "position")
    elif type(position) is np.ndarray and position.shape == (3,):
        x, y, z = finite_floats(tuple(position.tolist()), (3,), "position")
    else:
        x, y, z = finite_array(position, (3,), "position").tolist()
    if type(orientation_xyzw) is tuple and orientation_xyzw == IDENTITY:
        quaternion = IDENTITY
    else:
        quaternion = unit_quaternion(orientation_xyzw, "orientation_xyzw").tolist()
    return cdr.encode(*stamp_parts(stamp), frame_id, (x, y, z, *quaternion))


def pose_from_bytes(data: bytes) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """(position (3,) m, unit quaternion (4,) x, y, z, w, stamp (sec, nanosec)) of a serialized
    PoseStamped; refuses malformed bytes, non-finite values and a zero quaternion, naming the field."""
    sec, nanosec, _, values = cdr.decode(data, cdr.POSE_FIELDS, "PoseStamped")
    position = np.array(finite_floats(values[:3], (3,), "PoseStamped.pose.position"))
    return position, unit_quaternion(values[3:], "PoseStamped.pose.orientation"), (sec, nanosec)


def position_from_bytes(data: bytes) -> tuple[tuple[float, float, float], tuple[int, int]]:
    """(position (x, y, z) m as floats, stamp (sec, nanosec)) of a serialized PoseStamped, its orientation not read:
    what a 1 kHz loop that places a point needs; refuses malformed bytes and a non-finite position, naming the
    field."""
    sec, nanosec, _, values = cdr.decode(data, cdr.POSE_FIELDS, "PoseStamped")
    return finite_floats(values[:3], (3,), "PoseStamped.pose.position"), (sec, nanosec)
