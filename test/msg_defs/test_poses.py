"""msg_defs.poses: a position and a quaternion as Pose and PoseStamped and back, normalised, refusals by field; the
1 kHz paths: a PoseStamped written as bytes, and the position alone read from them."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import Pose, PoseStamped
from rclpy.serialization import deserialize_message, serialize_message

from msg_defs.poses import IDENTITY, pose_stamped, pose_stamped_bytes, pose_to_arrays, position_from_bytes


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


@pytest.mark.parametrize("component", [1e200, 1e-200, 1.7e308])
def test_quaternions_of_huge_or_tiny_components_normalise(component):
    pose = pose_stamped([0.0, 0.0, 0.0], (component, component, 0.0, 0.0), 0.0, "liver")
    _, q = pose_to_arrays(pose)
    np.testing.assert_allclose(q, [math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
    with pytest.raises(ValueError, match="non-zero"):
        pose_stamped([0.0, 0.0, 0.0], (0.0, 0.0, 0.0, 0.0), 0.0, "liver")


@pytest.mark.parametrize("position", [(0.1, -0.2, 0.3), np.array([0.1, -0.2, 0.3]), [0.1, -0.2, 0.3]])
@pytest.mark.parametrize("orientation", [IDENTITY, (0.0, 0.0, 0.0, 2.0), np.array([0.0, 0.0, 0.0, 1.0])])
def test_every_path_of_the_pose_bytes_is_the_pose_message(position, orientation):
    expected = pose_stamped(position, orientation, (4, 5), "phantom_base")
    data = pose_stamped_bytes(position, orientation, (4, 5), "phantom_base")
    assert deserialize_message(data, PoseStamped) == expected
    assert expected.pose.orientation.w == 1.0


@pytest.mark.parametrize("position", [(0.0, math.nan, 0.0), np.array([math.inf, 0.0, 0.0]), [0.0, 0.0, -math.inf]])
def test_the_pose_bytes_refuse_a_position_that_is_not_finite(position):
    with pytest.raises(ValueError, match="^position must be finite"):
        pose_stamped_bytes(position, IDENTITY, (4, 5), "phantom_base")


def test_the_position_alone_is_read_from_the_bytes_and_the_orientation_is_not():
    data = serialize_message(pose_stamped((0.25, -0.5, 0.125), (0.0, 0.0, 1.0, 1.0), (9, 10), "phantom_base"))
    assert position_from_bytes(data) == ((0.25, -0.5, 0.125), (9, 10))
    unread = deserialize_message(data, PoseStamped)
    unread.pose.orientation.z = unread.pose.orientation.w = 0.0  # a zero quaternion: not read, not refused
    assert position_from_bytes(serialize_message(unread)) == ((0.25, -0.5, 0.125), (9, 10))
    unread.pose.position.y = math.nan
    with pytest.raises(ValueError, match=r"^PoseStamped\.pose\.position must be finite"):
        position_from_bytes(serialize_message(unread))
