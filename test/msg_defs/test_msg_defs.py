"""msg_defs across its modules and below it: the rotations of the local model's normal
(liver_sim.base.geometry.rotations), and a node cloud and a skin Marker over loopback DDS. Each message module has
its own file: test_<module>.py."""
import time

import numpy as np
import pytest
from msg_samples import AXES, random_skin

from liver_sim.base.geometry.rotations import quaternion_from_z_axis, quaternion_to_matrix
from msg_defs.point_cloud import nodes_to_pointcloud2, pointcloud2_to_nodes
from msg_defs.skin import skin_marker_serialized
from msg_defs.topics import TOPICS


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


@pytest.mark.no_rate_loops  # a participant in a process of its own or this one: no loop keeps a rate
def test_pointcloud_and_serialized_marker_cross_loopback_dds(ros_domain_id, rng):
    """A PointCloud2 and a pre-serialized skin Marker published by one node arrive intact at another."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    positions, skin = rng.random((2000, 3)), random_skin(rng, 2000, 450)
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
