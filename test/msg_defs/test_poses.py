"""msg_defs.poses: a position and a quaternion as Pose and PoseStamped and back, normalised, refusals by field."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import Pose, PoseStamped

from msg_defs.poses import pose_stamped, pose_to_arrays


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
