"""msg_defs.topics: the topics table of docs/contract.md as data, and the QoS a device takes force commands with."""
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from msg_defs.topics import TOPICS


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
