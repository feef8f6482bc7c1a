"""msg_defs.forces: the force command in every output format and back, the tool wrench, and their refusals."""
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3, Wrench, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from msg_defs.forces import (
    FORCE_OUTPUT_FORMATS,
    force_from_message,
    force_message,
    force_message_type,
    wrench_stamped,
)
from msg_defs.stamps import seconds_from_stamp

STANDARD_FORCE_FORMATS = [fmt for fmt in FORCE_OUTPUT_FORMATS if fmt != "omni_feedback"]


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
