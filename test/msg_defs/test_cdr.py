"""msg_defs.cdr: the 1 kHz messages as bytes: the bytes rclpy writes, read back in either byte order, and
malformed or oversized bytes refused naming the field (directly, and through the pose and wrench codecs that use
it); a local-model Marker's fields read from and written as the bytes rclpy writes."""
import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, UVCoordinate

from msg_defs import cdr
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


# -- the codec itself, against rclpy's serializer
@pytest.mark.parametrize("frame_id", ["", "l", "ab", "abc", "liver", "phantom_base", "lëber"])
def test_encoded_pose_and_wrench_are_the_messages_rclpy_reads(frame_id):
    pose = (0.1, -0.2, 0.3, 0.0, 0.6, 0.0, 0.8)
    message = deserialize_message(cdr.encode(1_700_000_000, 999_999_999, frame_id, pose), PoseStamped)
    assert message.header == Header(stamp=Time(sec=1_700_000_000, nanosec=999_999_999), frame_id=frame_id)
    p, o = message.pose.position, message.pose.orientation
    assert (p.x, p.y, p.z, o.x, o.y, o.z, o.w) == pose
    wrench = (1.5, -0.5, 0.25, 0.0, 0.0, -0.125)
    message = deserialize_message(cdr.encode(-3, 7, frame_id, wrench), WrenchStamped)
    f, t = message.wrench.force, message.wrench.torque
    assert (message.header.stamp.sec, message.header.stamp.nanosec, message.header.frame_id) == (-3, 7, frame_id)
    assert (f.x, f.y, f.z, t.x, t.y, t.z) == wrench


@pytest.mark.parametrize("frame_id", ["", "l", "ab", "abc", "liver", "phantom_base", "lëber"])
def test_decoded_bytes_of_rclpy_give_the_stamp_the_frame_and_the_values(frame_id):
    message = PoseStamped(header=Header(stamp=Time(sec=12, nanosec=345), frame_id=frame_id),
                          pose=Pose(position=Point(x=1.0, y=2.0, z=3.0), orientation=Quaternion(x=0.5, w=0.5)))
    data = serialize_message(message)
    assert cdr.decode(data, cdr.POSE_FIELDS, "PoseStamped") == (12, 345, frame_id, (1.0, 2.0, 3.0, 0.5, 0.0, 0.0, 0.5))
    assert cdr.stamp(data, "PoseStamped") == (12, 345)


def test_a_message_of_max_bytes_is_read_and_one_byte_more_is_refused_before_reading():
    data = cdr.encode(1, 2, "liver", (0.0,) * cdr.POSE_FIELDS)
    limit = cdr.MAX_BYTES["PoseStamped"]
    padded = data + bytes(limit - len(data))
    assert len(padded) == limit and cdr.decode(padded, cdr.POSE_FIELDS, "PoseStamped")[:3] == (1, 2, "liver")
    with pytest.raises(ValueError, match=r"^PoseStamped: 1025 bytes, more than the 1024"):
        cdr.decode(padded + b"\x00", cdr.POSE_FIELDS, "PoseStamped")
    with pytest.raises(ValueError, match=r"^Marker: 4097 bytes, more than the 4096"):
        cdr.marker_fields(bytes(4097))  # not even a CDR header: refused for its size first


@pytest.mark.parametrize("cut", [0, 15, 20, 27])
def test_bytes_cut_before_the_payload_are_refused_naming_the_message(cut):
    data = cdr.encode(1, 2, "liver", (0.0,) * cdr.WRENCH_FIELDS)
    with pytest.raises(ValueError, match=r"^WrenchStamped(\.header\.frame_id)?: (not a CDR message|truncated|bad)"):
        cdr.decode(data[:cut], cdr.WRENCH_FIELDS, "WrenchStamped")


# -- the local-model Marker
MARKER = Marker(header=Header(stamp=Time(sec=12, nanosec=345), frame_id="liver"), ns="local_model", id=3,
                type=Marker.SPHERE, action=Marker.ADD,
                pose=Pose(position=Point(x=0.1, y=-0.2, z=0.3), orientation=Quaternion(x=0.0, y=0.6, z=0.0, w=0.8)),
                scale=Vector3(x=0.1, y=0.2, z=0.3), color=ColorRGBA(r=0.5, g=0.25, b=0.125, a=1.0),
                lifetime=Duration(sec=1, nanosec=5), text="stiffness_n_per_m=12.5")
MARKER_FIELDS = {"stamp": (12, 345), "frame_id": "liver", "ns": "local_model", "id": 3, "type": Marker.SPHERE,
                 "action": Marker.ADD, "pose": (0.1, -0.2, 0.3, 0.0, 0.6, 0.0, 0.8), "scale": (0.1, 0.2, 0.3),
                 "lifetime": (1, 5), "text": "stiffness_n_per_m=12.5"}


def test_a_markers_fields_are_read_from_the_bytes_rclpy_writes_past_every_field_it_may_fill():
    assert cdr.marker_fields(serialize_message(MARKER)) == MARKER_FIELDS
    full = deserialize_message(serialize_message(MARKER), Marker)
    full.points = [Point(x=float(k)) for k in range(3)]
    full.colors = [ColorRGBA(g=1.0)] * 2
    full.texture_resource, full.texture.header.frame_id, full.texture.data = "embedded://t", "cam", [1, 2, 3, 4, 5]
    full.uv_coordinates = [UVCoordinate(u=0.5, v=0.25)] * 3
    full.mesh_resource = "package://liver/mesh.dae"
    assert cdr.marker_fields(serialize_message(full)) == MARKER_FIELDS


@pytest.mark.parametrize("frame_id, ns, text", [("liver", "local_model", "stiffness_n_per_m=12.5"), ("", "", ""),
                                                ("ab", "abc", "k=1 x"), ("lëber", "n", "é")])
def test_marker_bytes_are_the_message_rclpy_writes(frame_id, ns, text):
    """Byte for byte, but for the padding rclpy leaves uninitialised, which marker_bytes writes as zero."""
    expected = deserialize_message(serialize_message(MARKER), Marker)
    expected.header.frame_id, expected.ns, expected.text = frame_id, ns, text
    data = cdr.marker_bytes((12, 345), frame_id, ns, 3, Marker.SPHERE, Marker.ADD, MARKER_FIELDS["pose"],
                            MARKER_FIELDS["scale"], (0.5, 0.25, 0.125, 1.0), (1, 5), text)
    reference = serialize_message(expected)
    assert len(data) == len(reference)
    assert deserialize_message(data, Marker) == expected
    assert all(ours == 0 for ours, theirs in zip(data, reference) if ours != theirs), "only padding differs"
    assert cdr.marker_fields(data) == {**MARKER_FIELDS, "frame_id": frame_id, "ns": ns, "text": text}
