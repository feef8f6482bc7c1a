"""msg_defs.cdr: the 1 kHz messages as bytes: the bytes rclpy writes, read back in either byte order, and
malformed or oversized bytes refused naming the field (through the pose and wrench codecs that use it)."""
import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import serialize_message

from msg_defs.forces import force_from_bytes, force_message, force_message_bytes, wrench_stamped, wrench_stamped_bytes
from msg_defs.poses import pose_from_bytes, pose_stamped, pose_stamped_bytes
from msg_defs.stamps import stamp_s_from_bytes


def _padding_zeroed(data: bytes, frame_id: str) -> bytes:
    """CDR bytes with the padding after the header's frame_id zeroed (rclpy leaves it uninitialised)."""
    end = 16 + len(frame_id) + 1
    start = end + (-(end - 4) % 8)
    return data[:end] + bytes(start - end) + data[start:]


@pytest.mark.parametrize("frame_id", ["", "a", "liver", "phantom_base", "frame_of_nine"])
def test_serialized_pose_and_wrench_are_the_bytes_rclpy_writes(frame_id, rng):
    stamp = Time(sec=1_700_000_123, nanosec=987_654_321)
    position, quaternion = rng.normal(size=3), rng.normal(size=4)
    expected = serialize_message(pose_stamped(position, quaternion, stamp, frame_id))
    assert pose_stamped_bytes(position, quaternion, stamp, frame_id) == _padding_zeroed(expected, frame_id)
    force = rng.normal(size=3)
    expected = serialize_message(wrench_stamped(force, stamp, frame_id))
    assert wrench_stamped_bytes(force, stamp, frame_id) == _padding_zeroed(expected, frame_id)
    assert force_message_bytes("wrench_stamped", force, stamp, frame_id) == _padding_zeroed(expected, frame_id)


@pytest.mark.parametrize("frame_id", ["", "liver", "phantom_base"])
def test_serialized_pose_and_wrench_read_back(frame_id, rng):
    position, quaternion = rng.normal(size=3), rng.normal(size=4)
    data = serialize_message(pose_stamped(position, quaternion, (5, 17), frame_id))
    back_position, back_quaternion, stamp = pose_from_bytes(data)
    np.testing.assert_array_equal(back_position, position)
    np.testing.assert_allclose(back_quaternion, quaternion / np.linalg.norm(quaternion))
    assert stamp == (5, 17) and stamp_s_from_bytes(data, "PoseStamped") == 5 + 17e-9
    force = rng.normal(size=3)
    for fmt in ("wrench_stamped", "wrench", "vector3", "float64_array"):
        data = force_message_bytes(fmt, force, Time(sec=2), frame_id)
        np.testing.assert_array_equal(force_from_bytes(fmt, data), force)


def test_big_endian_cdr_pose_is_read():
    head = struct.pack(">iII", 3, 4, 6) + b"liver\x00" + bytes(6)
    data = b"\x00\x00\x00\x00" + head + struct.pack(">7d", 0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 2.0)
    position, quaternion, stamp = pose_from_bytes(data)
    assert position.tolist() == [0.1, 0.2, 0.3] and quaternion.tolist() == [0.0, 0.0, 0.0, 1.0] and stamp == (3, 4)


def test_malformed_serialized_pose_and_force_are_refused_by_field():
    good = pose_stamped_bytes((0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0), 1.0, "liver")
    with pytest.raises(ValueError, match="PoseStamped: truncated"):
        pose_from_bytes(good[:-1])
    with pytest.raises(ValueError, match="PoseStamped: not a CDR message"):
        pose_from_bytes(b"\x07" * 40)
    with pytest.raises(ValueError, match=r"PoseStamped.header.frame_id: bad string length"):
        pose_from_bytes(good[:12] + struct.pack("<I", 10_000) + good[16:])
    nan_position = good[:-56] + struct.pack("<d", float("nan")) + good[-48:]
    with pytest.raises(ValueError, match=r"PoseStamped.pose.position must be finite"):
        pose_from_bytes(nan_position)
    with pytest.raises(ValueError, match=r"PoseStamped.pose.orientation must be a non-zero quaternion"):
        pose_from_bytes(good[:-32] + bytes(32))
    force = wrench_stamped_bytes((0.0, 1.0, 0.0), 1.0, "phantom_base")
    with pytest.raises(ValueError, match="WrenchStamped force must be finite"):
        force_from_bytes("wrench_stamped", force[:-48] + struct.pack("<d", float("inf")) + force[-40:])
    with pytest.raises(ValueError, match="force must be finite"):
        wrench_stamped_bytes((0.0, float("nan"), 0.0), 1.0, "phantom_base")


def test_oversized_serialized_pose_and_force_are_refused():
    long_frame = "f" * 2000
    with pytest.raises(ValueError, match="PoseStamped: .* bytes, more than the 1024"):
        pose_from_bytes(pose_stamped_bytes([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], (1, 2), long_frame))
    with pytest.raises(ValueError, match="WrenchStamped: .* bytes, more than the 1024"):
        force_from_bytes("wrench_stamped", force_message_bytes("wrench_stamped", np.zeros(3), (1, 2), long_frame))
    huge = serialize_message(force_message("float64_array", np.zeros(3), (1, 2), "f"))
    with pytest.raises(ValueError, match="more than 1024"):
        force_from_bytes("float64_array", huge + bytes(2000))
