"""msg_defs.topics: the topics table of docs/contract.md as data, the depth that keeps CATCH_UP_S of messages, and
the QoS a reader takes each kind of input with, matched against the writers' by rclpy's own compatibility check."""
import pytest
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSCompatibility,
    QoSProfile,
    ReliabilityPolicy,
    qos_check_compatible,
)
from sensor_msgs.msg import PointCloud2

from msg_defs.topics import (
    CATCH_UP_S,
    TOPICS,
    batch_qos,
    catch_up_depth,
    device_command_qos,
    latched_reader_qos,
    loop_input_qos,
)

#: ROS's default publisher QoS (reliable, volatile, keep last 10): what a driver or a script may publish with.
ROS_DEFAULT = QoSProfile(depth=10)


def compatible(writer, reader) -> bool:
    """Whether a reader of QoS `reader` matches a writer of QoS `writer` (rclpy: an ERROR means no match)."""
    return qos_check_compatible(writer, reader)[0] != QoSCompatibility.ERROR


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


def test_devices_subscribe_to_force_commands_volatile_so_no_old_command_is_replayed_to_them():
    from rclpy.qos import DurabilityPolicy

    from msg_defs.topics import device_command_qos

    device = device_command_qos(TOPICS["servo_cf"])
    assert TOPICS["servo_cf"].qos.durability == DurabilityPolicy.TRANSIENT_LOCAL  # the recorder's catch-up
    assert device.durability == DurabilityPolicy.VOLATILE
    assert device.reliability == TOPICS["servo_cf"].qos.reliability and device.depth == TOPICS["servo_cf"].depth


def test_a_catch_up_depth_keeps_its_seconds_of_messages_and_at_least_one():
    assert CATCH_UP_S == 5.0
    assert catch_up_depth(150.0) == 750 and catch_up_depth(1000.0) == 5000
    assert catch_up_depth(30.0, seconds=2.0) == 60
    assert catch_up_depth(0.05) == 1  # a quarter of a message in 5 s: still one kept


@pytest.mark.parametrize("key", sorted(TOPICS))
def test_a_batch_reader_keeps_its_depth_with_the_topics_reliability_and_durability(key):
    qos = batch_qos(TOPICS[key], 321)
    assert qos.depth == 321 and qos.history == HistoryPolicy.KEEP_LAST
    assert (qos.reliability, qos.durability) == (TOPICS[key].qos.reliability, TOPICS[key].qos.durability)
    assert compatible(TOPICS[key].qos, qos)


@pytest.mark.parametrize("key", sorted(TOPICS))
def test_a_loop_input_is_read_best_effort_and_volatile_and_matches_every_writer(key):
    qos = loop_input_qos(TOPICS[key])
    assert (qos.reliability, qos.durability, qos.history, qos.depth) == (
        ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, HistoryPolicy.KEEP_LAST, 1)
    assert loop_input_qos(TOPICS[key], depth=8).depth == 8
    assert compatible(TOPICS[key].qos, qos) and compatible(ROS_DEFAULT, qos)


def test_a_latched_input_is_read_reliable_transient_local_keeping_all():
    qos = latched_reader_qos(TOPICS["device_map"])
    assert (qos.reliability, qos.durability, qos.history) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, HistoryPolicy.KEEP_ALL)
    assert compatible(TOPICS["device_map"].qos, qos)


def test_a_device_matches_the_bridges_force_writer_and_a_drivers_default_one():
    qos = device_command_qos(TOPICS["servo_cf"])
    assert compatible(TOPICS["servo_cf"].qos, qos) and compatible(ROS_DEFAULT, qos)
