"""liver_physics as a real process: it takes its tool's poses only from its `tool_node` (haptic_bridge.sources), so a
peer publishing on the tool pose topic under another name cannot move the tool into the tissue.

Every wait is bounded; nothing asserts on timing.
"""
import math

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import PoseStamped
from node_processes import Ros, start, statuses, stop

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from msg_defs.topics import TOPICS

TOOL_RADIUS_M = 0.015  # config/liver_physics.yaml
#: How deep the published tool sphere reaches into the liver at rest (m).
PRESS_M = 0.005
#: A contact force no resting liver gives (N).
FELT_N = 0.05
LOOP = "liver_physics: loop"


@pytest.fixture
def ros(ros_domain_id):
    session = Ros("test_physics_sources")
    try:
        yield session
    finally:
        session.close()


def _pressing_pose(node) -> PoseStamped:
    """A tool pose whose sphere reaches PRESS_M into the top of the default liver at rest, stamped now."""
    tip = press_anchor(default_liver()) + [0.0, 0.0, TOOL_RADIUS_M - PRESS_M]
    pose = PoseStamped()
    pose.header.stamp = node.get_clock().now().to_msg()
    pose.header.frame_id = "liver"
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in tip)
    pose.pose.orientation.w = 1.0
    return pose


def _felt_n(wrenches) -> float:
    return max((math.hypot(w.wrench.force.x, w.wrench.force.y, w.wrench.force.z) for w in wrenches), default=0.0)


def test_tool_poses_from_a_node_not_named_by_tool_node_are_refused_and_move_nothing(ros, ros_env):
    wrenches = ros.collect("tool_wrench")
    diagnostics = ros.collect("diagnostics")
    physics = start("liver_physics", {}, ros_env)
    impostor = rclpy.create_node("impostor_tool", context=ros.context)
    source = rclpy.create_node("liver_tool", context=ros.context)  # the default tool_node
    try:
        ros.wait_until(lambda: statuses(diagnostics, LOOP) and len(wrenches) > 10, "the physics running", physics)
        refused_before = int(statuses(diagnostics, LOOP)[-1]["refused_tool_poses"])
        for node in (impostor, source):
            node.publisher = node.create_publisher(PoseStamped, TOPICS["tool_pose"].name, TOPICS["tool_pose"].qos)

        def press_from(node) -> None:
            node.publisher.publish(_pressing_pose(node))
            ros.executor.spin_once(timeout_sec=0.01)

        ros.wait_until(lambda: press_from(impostor) or int(statuses(diagnostics, LOOP)[-1]["refused_tool_poses"])
                       >= refused_before + 20, "the impostor's poses refused", physics)
        from_impostor = len(wrenches)
        assert _felt_n(wrenches) < FELT_N, "the impostor's pose pressed the tool into the liver"
        assert statuses(diagnostics, LOOP)[-1]["tool_pose_source"] == "ok"
        impostor.destroy_node()
        ros.wait_until(lambda: press_from(source) or _felt_n(wrenches[from_impostor:]) > FELT_N,
                       "the tool_node's pose felt", physics)
    finally:
        source.destroy_node()
        err = stop(physics)
    assert physics.returncode == 0, err
    forces = np.array([[w.wrench.force.x, w.wrench.force.y, w.wrench.force.z] for w in wrenches[from_impostor:]])
    assert forces[:, 2].max() > FELT_N, "the liver pushes the pressing tool up"
