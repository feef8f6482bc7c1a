"""msg_defs: numpy ↔ ROS message round trips, refusals naming the field, and one trip over loopback DDS."""
import math
import struct
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseStamped, Vector3, Wrench, WrenchStamped
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField
from shape_msgs.msg import Mesh
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker

from liver_sim.base.geometry.rotations import quaternion_from_z_axis, quaternion_to_matrix
from msg_defs.device_map import device_map_from_message, device_map_message
from msg_defs.forces import (
    FORCE_OUTPUT_FORMATS,
    force_from_bytes,
    force_from_message,
    force_message,
    force_message_bytes,
    force_message_type,
    wrench_stamped,
    wrench_stamped_bytes,
)
from msg_defs.point_cloud import nodes_to_pointcloud2, pointcloud2_to_nodes
from msg_defs.poses import pose_from_bytes, pose_stamped, pose_stamped_bytes, pose_to_arrays
from msg_defs.skin import mesh_msg_to_arrays, skin_marker, skin_marker_serialized, skin_mesh_msg
from msg_defs.stamps import seconds_from_stamp, stamp_from_seconds, stamp_s_from_bytes
from msg_defs.topics import TOPICS

STANDARD_FORCE_FORMATS = [fmt for fmt in FORCE_OUTPUT_FORMATS if fmt != "omni_feedback"]
AXES = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0.3, -0.2, -0.9)]


# ---------------------------------------------------------------- time

def test_stamp_round_trip_to_the_nanosecond():
    stamp = stamp_from_seconds(1_700_000_000.25)
    assert (stamp.sec, stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert seconds_from_stamp(stamp_from_seconds(12.345678901)) == pytest.approx(12.345678901, abs=1e-9)
    carried = stamp_from_seconds(2.9999999999)
    assert (carried.sec, carried.nanosec) == (3, 0)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), 2.0 ** 31])
def test_stamp_refuses_negative_non_finite_and_overflowing_times(bad):
    with pytest.raises(ValueError, match="stamp"):
        stamp_from_seconds(bad)


# ---------------------------------------------------------------- PointCloud2

def test_pointcloud_round_trip_is_exact_in_float32(rng):
    positions = rng.normal(scale=0.1, size=(2000, 3))
    msg = nodes_to_pointcloud2(positions, 3.5, "liver")
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 2000, 12, 24000)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, PointField.FLOAT32, 1), ("y", 4, PointField.FLOAT32, 1), ("z", 8, PointField.FLOAT32, 1)]
    assert msg.is_dense and not msg.is_bigendian
    assert msg.header.frame_id == "liver" and seconds_from_stamp(msg.header.stamp) == 3.5
    back = pointcloud2_to_nodes(deserialize_message(serialize_message(msg), PointCloud2))
    assert back.dtype == np.float64 and back.shape == (2000, 3)
    np.testing.assert_array_equal(back, positions.astype(np.float32))


def test_pointcloud_accepts_other_layouts(rng):
    """Foreign clouds: padded points, fields out of order, extra fields, big-endian, two rows."""
    xyz = rng.random((6, 3)).astype(np.float32)
    for endian, bigendian in (("<", False), (">", True)):
        layout = np.dtype({"names": ["intensity", "z", "x", "y"], "formats": [endian + "f4"] * 4,
                           "offsets": [0, 4, 12, 20], "itemsize": 32})
        records = np.zeros(6, dtype=layout)
        records["x"], records["y"], records["z"] = xyz.T
        fields = [PointField(name=name, offset=offset, datatype=PointField.FLOAT32, count=1)
                  for name, offset in (("intensity", 0), ("z", 4), ("x", 12), ("y", 20))]
        msg = PointCloud2(height=2, width=3, fields=fields, is_bigendian=bigendian, point_step=32, row_step=96,
                          data=records.tobytes(), is_dense=True)
        np.testing.assert_array_equal(pointcloud2_to_nodes(msg), xyz)


def _cloud_with(**changes):
    msg = nodes_to_pointcloud2(np.arange(30.0).reshape(10, 3), 0.0, "liver")
    for key, value in changes.items():
        setattr(msg, key, value)
    return msg


def _field(name, offset, datatype=PointField.FLOAT32):
    return PointField(name=name, offset=offset, datatype=datatype, count=1)


def _nan_data():
    data = np.arange(30.0, dtype="<f4")
    data[17] = np.nan
    return data.tobytes()


@pytest.mark.parametrize("changes, message", [
    ({"data": bytes(100)}, r"PointCloud2\.data has 100 bytes, expected row_step\*height = 120"),
    ({"row_step": 100}, r"PointCloud2\.row_step is 100"),
    ({"point_step": 8, "row_step": 80}, r"PointCloud2\.point_step is 8"),
    ({"fields": [_field("x", 0), _field("z", 8)]}, r"PointCloud2\.fields has no 'y' field"),
    ({"fields": [_field("x", 0), _field("y", 4, PointField.FLOAT64), _field("z", 8)]},
     r"PointCloud2\.fields\['y'\]\.datatype is 8, expected 7"),
    ({"fields": [_field("x", 0), _field("y", 4), _field("z", 10)]}, r"PointCloud2\.fields\['z'\]\.offset is 10"),
    ({"data": _nan_data()}, r"PointCloud2\.data holds non-finite coordinates \(first at point 5\)"),
], ids=["data length", "row_step", "point_step", "missing field", "datatype", "offset", "NaN"])
def test_malformed_pointcloud_is_refused_naming_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        pointcloud2_to_nodes(_cloud_with(**changes))


@pytest.mark.parametrize("positions, message", [
    (np.array([[0.0, np.nan, 0.0]]), r"positions must be finite .* at index \[0, 1\]"),
    (np.array([[0.0, 1e39, 0.0]]), r"positions must be finite \(float32\)"),
    (np.zeros((4, 2)), r"positions must have shape \(N, 3\)"),
])
def test_pointcloud_builder_refuses_what_would_not_be_finite_float32(positions, message):
    with pytest.raises(ValueError, match=message):
        nodes_to_pointcloud2(positions, 0.0, "liver")


# ---------------------------------------------------------------- skin: Mesh and Marker

def _skin(rng, n_points, n_triangles):
    return rng.integers(0, n_points, size=(n_triangles, 3))


def test_mesh_round_trip(rng):
    points, skin = rng.random((40, 3)), _skin(rng, 40, 60)
    msg = deserialize_message(serialize_message(skin_mesh_msg(skin, points)), Mesh)
    back_skin, back_points = mesh_msg_to_arrays(msg)
    np.testing.assert_array_equal(back_skin, skin)
    np.testing.assert_array_equal(back_points, points)
    assert back_skin.dtype == np.int64


def test_mesh_refuses_indices_out_of_range_both_ways(rng):
    points = rng.random((4, 3))
    with pytest.raises(ValueError, match=r"skin holds node indices outside \[0, 4\)"):
        skin_mesh_msg(np.array([[0, 1, 4]]), points)
    msg = skin_mesh_msg(np.array([[0, 1, 3]]), points)
    msg.vertices.pop()
    with pytest.raises(ValueError, match=r"Mesh\.triangles holds node indices outside \[0, 3\)"):
        mesh_msg_to_arrays(msg)
    msg.vertices[0].y = float("inf")
    with pytest.raises(ValueError, match=r"Mesh\.vertices must be finite"):
        mesh_msg_to_arrays(msg)


def test_skin_marker_lists_the_triangle_corners_in_order(rng):
    positions, skin = rng.random((30, 3)), _skin(rng, 30, 20)
    marker = skin_marker(positions, skin, 2.0, "liver")
    assert (marker.ns, marker.id, marker.type, marker.action) == ("liver", 0, Marker.TRIANGLE_LIST, Marker.ADD)
    assert marker.pose.orientation.w == 1.0 and marker.color.a == 1.0
    corners = np.array([(p.x, p.y, p.z) for p in marker.points])
    np.testing.assert_array_equal(corners, positions[skin].reshape(-1, 3))


@pytest.mark.parametrize("n_triangles", [0, 1, 450])
def test_serialized_skin_marker_is_the_same_message(rng, n_triangles):
    positions, skin = rng.random((300, 3)), _skin(rng, 300, n_triangles)
    stamp = stamp_from_seconds(5.25)
    expected = deserialize_message(serialize_message(skin_marker(positions, skin, stamp, "liver")), Marker)
    assert deserialize_message(skin_marker_serialized(positions, skin, stamp, "liver"), Marker) == expected


# ---------------------------------------------------------------- rotations and poses

@pytest.mark.parametrize("normal", AXES)
def test_quaternion_from_z_axis_maps_z_to_the_normal(normal):
    q = quaternion_from_z_axis(normal)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    np.testing.assert_allclose(quaternion_to_matrix(q)[:, 2], np.asarray(normal) / np.linalg.norm(normal), atol=1e-12)


def test_quaternion_from_z_axis_is_the_shortest_arc_and_refuses_zero(rng):
    for normal in rng.normal(size=(50, 3)):
        rotation = quaternion_to_matrix(quaternion_from_z_axis(normal))
        unit = normal / np.linalg.norm(normal)
        np.testing.assert_allclose(rotation[:, 2], unit, atol=1e-12)
        np.testing.assert_allclose(rotation @ np.cross([0, 0, 1], unit), np.cross([0, 0, 1], unit), atol=1e-12)
    with pytest.raises(ValueError, match="normal must be non-zero"):
        quaternion_from_z_axis((0, 0, 0))


def test_pose_round_trip_normalises_the_quaternion():
    msg = pose_stamped((0.1, -0.2, 0.3), (0.0, 0.0, 2.0, 2.0), 1.0, "liver")
    assert msg.header.frame_id == "liver"
    for pose in (msg, msg.pose):
        position, orientation = pose_to_arrays(pose)
        np.testing.assert_array_equal(position, (0.1, -0.2, 0.3))
        np.testing.assert_allclose(orientation, (0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)))


def test_pose_with_bad_fields_is_refused_by_name():
    bad_position = Pose()
    bad_position.position.z = float("nan")
    with pytest.raises(ValueError, match=r"Pose\.position must be finite"):
        pose_to_arrays(bad_position)
    zero_orientation = PoseStamped()
    zero_orientation.pose.orientation.w = 0.0
    with pytest.raises(ValueError, match=r"PoseStamped\.pose\.orientation must be a non-zero quaternion"):
        pose_to_arrays(zero_orientation)
    with pytest.raises(ValueError, match="orientation_xyzw"):
        pose_stamped((0, 0, 0), (0, 0, 0, 0), 0.0, "liver")


# ---------------------------------------------------------------- forces

def test_wrench_stamped_carries_force_torque_and_header():
    msg = wrench_stamped((0.5, -1.0, 1.5), 7.0, "liver", torque=(0.0, 0.1, 0.0))
    wrench = msg.wrench
    assert (wrench.force.x, wrench.force.y, wrench.force.z, wrench.torque.y) == (0.5, -1.0, 1.5, 0.1)
    assert msg.header.frame_id == "liver" and seconds_from_stamp(msg.header.stamp) == 7.0
    with pytest.raises(ValueError, match="force must be finite"):
        wrench_stamped((0.0, float("inf"), 0.0), 7.0, "liver")


@pytest.mark.parametrize("fmt, msg_type", [("wrench_stamped", WrenchStamped), ("wrench", Wrench),
                                           ("vector3", Vector3), ("float64_array", Float64MultiArray)])
def test_each_force_output_format_carries_the_same_force(fmt, msg_type):
    force = (0.25, -1.5, 0.75)
    assert force_message_type(fmt) is msg_type
    msg = force_message(fmt, force, Time(sec=3), "phantom_base")
    assert isinstance(msg, msg_type)
    back = force_from_message(fmt, deserialize_message(serialize_message(msg), msg_type))
    np.testing.assert_array_equal(back, force)


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


def test_force_output_refusals():
    with pytest.raises(ValueError, match=r"needs omni_msgs \(Geomagic Touch ROS 2 driver workspace\) sourced"):
        force_message_type("omni_feedback")
    with pytest.raises(ValueError, match="needs omni_msgs"):
        force_message("omni_feedback", (0.0, 0.0, 1.0), 0.0, "phantom_base")
    with pytest.raises(ValueError, match="force_output must be one of"):
        force_message_type("twist")
    with pytest.raises(ValueError, match=r"Float64MultiArray\.data has 2 values, expected 3"):
        force_from_message("float64_array", Float64MultiArray(data=[1.0, 2.0]))
    with pytest.raises(ValueError, match="'vector3' carries Vector3, got Wrench"):
        force_from_message("vector3", Wrench())
    with pytest.raises(ValueError, match="Vector3 force must be finite"):
        force_from_message("vector3", Vector3(x=float("nan")))
    for fmt in STANDARD_FORCE_FORMATS:
        with pytest.raises(ValueError, match="force must be finite"):
            force_message(fmt, (0.0, float("nan"), 0.0), 0.0, "phantom_base")


# ---------------------------------------------------------------- topics

def test_topics_follow_the_design_table():
    expected = {
        "nodes": ("/liver/nodes", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 750),
        "surface": ("/liver/surface", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 750),
        "marker": ("/liver/marker", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 150),
        "contact_plane": ("/liver/contact_plane", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 750),
        "tool_wrench": ("/liver/tool_wrench", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 750),
        "tool_pose": ("/tool/pose", ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 1),
        "measured_cp": ("/phantom/measured_cp", ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 1),
        "servo_cf": ("/phantom/servo_cf", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 5000),
        "diagnostics": ("/diagnostics", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 5),
        "device_map": ("/tool/device_map", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 1),
    }
    assert set(TOPICS) == set(expected)
    for key, (name, reliability, durability, depth) in expected.items():
        topic = TOPICS[key]
        assert (topic.name, topic.qos.reliability, topic.qos.durability, topic.qos.depth) == (
            name, reliability, durability, depth), key
    assert TOPICS["nodes"].type is PointCloud2 and TOPICS["servo_cf"].type is None


# ---------------------------------------------------------------- on the wire

@pytest.mark.no_rate_loops  # a participant in a process of its own or this one: no loop keeps a rate
def test_pointcloud_and_serialized_marker_cross_loopback_dds(ros_domain_id, rng):
    """A PointCloud2 and a pre-serialized skin Marker published by one node arrive intact at another."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    positions, skin = rng.random((2000, 3)), _skin(rng, 2000, 450)
    cloud = nodes_to_pointcloud2(positions, 9.0, "liver")
    marker_bytes = skin_marker_serialized(positions, skin, 9.0, "liver")
    received = {}
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain_id)
    try:
        sender = rclpy.create_node("msg_defs_sender", context=context)
        receiver = rclpy.create_node("msg_defs_receiver", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(receiver)
        topics = {"nodes": (TOPICS["nodes"], cloud), "marker": (TOPICS["marker"], marker_bytes)}
        publishers = {}
        for key, (topic, _) in topics.items():
            name = f"/msg_defs_test{topic.name}"
            publishers[key] = sender.create_publisher(topic.type, name, topic.qos)
            receiver.create_subscription(topic.type, name, lambda msg, key=key: received.setdefault(key, msg),
                                         topic.qos)
        deadline = time.monotonic() + 5.0
        while len(received) < len(topics) and time.monotonic() < deadline:
            for key, (_, message) in topics.items():
                if key not in received:
                    publishers[key].publish(message)
            executor.spin_once(timeout_sec=0.05)
        executor.shutdown()
        sender.destroy_node()
        receiver.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert set(received) == set(topics), f"received only {sorted(received)} within 5 s"
    np.testing.assert_array_equal(pointcloud2_to_nodes(received["nodes"]), positions.astype(np.float32))
    assert received["nodes"].header.frame_id == "liver"
    corners = np.array([(p.x, p.y, p.z) for p in received["marker"].points])
    np.testing.assert_array_equal(corners, positions[skin].reshape(-1, 3))


# ---------------------------------------------------------------- the device map, quaternions at the limits

def test_device_map_round_trips_and_refuses_a_bad_message():
    from liver_sim.base.geometry.device_map import DeviceMap

    original = DeviceMap([0.0, math.sin(0.4), 0.0, math.cos(0.4)], [0.1, -0.2, 0.3], 0.5)
    message = device_map_message(original)
    back = device_map_from_message(message)
    np.testing.assert_allclose(back.rotation, original.rotation, atol=1e-12)
    np.testing.assert_array_equal(back.translation, original.translation)
    assert back.scale == 0.5
    message.data[7] = -1.0
    with pytest.raises(ValueError, match="scale"):
        device_map_from_message(message)
    message.data[7], message.data[4] = 0.5, float("nan")
    with pytest.raises(ValueError, match="finite"):
        device_map_from_message(message)
    message.layout.dim = message.layout.dim[:2]
    with pytest.raises(ValueError, match="layout"):
        device_map_from_message(message)


@pytest.mark.parametrize("component", [1e200, 1e-200, 1.7e308])
def test_quaternions_of_huge_or_tiny_components_normalise(component):
    pose = pose_stamped([0.0, 0.0, 0.0], (component, component, 0.0, 0.0), 0.0, "liver")
    _, q = pose_to_arrays(pose)
    np.testing.assert_allclose(q, [math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
    with pytest.raises(ValueError, match="non-zero"):
        pose_stamped([0.0, 0.0, 0.0], (0.0, 0.0, 0.0, 0.0), 0.0, "liver")


def test_devices_subscribe_to_force_commands_volatile_so_no_old_command_is_replayed_to_them():
    from rclpy.qos import DurabilityPolicy

    from msg_defs.topics import device_command_qos

    device = device_command_qos(TOPICS["servo_cf"])
    assert TOPICS["servo_cf"].qos.durability == DurabilityPolicy.TRANSIENT_LOCAL  # the recorder's catch-up
    assert device.durability == DurabilityPolicy.VOLATILE
    assert device.reliability == TOPICS["servo_cf"].qos.reliability and device.depth == TOPICS["servo_cf"].depth


def test_oversized_serialized_pose_and_force_are_refused():
    long_frame = "f" * 2000
    with pytest.raises(ValueError, match="PoseStamped: .* bytes, more than the 1024"):
        pose_from_bytes(pose_stamped_bytes([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], (1, 2), long_frame))
    with pytest.raises(ValueError, match="WrenchStamped: .* bytes, more than the 1024"):
        force_from_bytes("wrench_stamped", force_message_bytes("wrench_stamped", np.zeros(3), (1, 2), long_frame))
    huge = serialize_message(force_message("float64_array", np.zeros(3), (1, 2), "f"))
    with pytest.raises(ValueError, match="more than 1024"):
        force_from_bytes("float64_array", huge + bytes(2000))
