"""A test publisher process: once `liver-sim record` has subscribed, sends a known number of messages
at the product's rates and QoS — force commands and tool poses at 1 kHz, node positions at 150 Hz —
then prints the counts it sent as JSON.  Usage: session_publisher.py TICKS (1 ms each) [other].

With `other`: force commands as geometry_msgs/Vector3 (force_output: vector3) and std_msgs/String on
/custom/topic instead, every tick.
"""
import json
import sys
import time

import rclpy
from rclpy.duration import Duration
from waiting import wait_for

from liver_sim.mesh.liver_shape import default_liver
from msg_defs.forces import force_message, force_message_type, wrench_stamped
from msg_defs.point_cloud import nodes_to_pointcloud2
from msg_defs.poses import pose_stamped
from msg_defs.topics import TOPICS


def main(ticks: int, other: bool) -> None:
    rclpy.init()
    node = rclpy.create_node("session_publisher")
    if other:
        publish_other(node, ticks)
        return
    nodes = default_liver().points
    publishers = {key: node.create_publisher(TOPICS[key].type or force_message_type("wrench_stamped"),
                                             TOPICS[key].name, TOPICS[key].qos)
                  for key in ("servo_cf", "tool_pose", "nodes")}
    wait_for_subscribers(publishers.values())
    counts = dict.fromkeys(publishers, 0)
    print("publishing", flush=True)
    start = time.monotonic()
    for k in range(ticks):
        while time.monotonic() < start + k * 0.001:
            time.sleep(0.0002)
        t = 1000.0 + k * 0.001
        publishers["servo_cf"].publish(wrench_stamped([0.0, 0.0, k * 1e-4], t, "phantom_base"))
        publishers["tool_pose"].publish(pose_stamped([0.0, 0.0, 0.1 + k * 1e-6], [0, 0, 0, 1], t, "liver"))
        counts["servo_cf"] += 1
        counts["tool_pose"] += 1
        if (k * 150) // 1000 != ((k - 1) * 150) // 1000 or k == 0:
            publishers["nodes"].publish(nodes_to_pointcloud2(nodes + k * 1e-6, t, "liver"))
            counts["nodes"] += 1
    for publisher in publishers.values():  # reliable messages still in flight reach the recorder first
        publisher.wait_for_all_acked(Duration(seconds=5.0))
    print(json.dumps({TOPICS[key].name: n for key, n in counts.items()}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def wait_for_subscribers(publishers) -> None:
    wait_for(lambda: all(p.get_subscription_count() > 0 for p in publishers), 60.0, "a recorder subscribed")
    time.sleep(0.5)  # both sides have matched: let the reliable handshakes finish


def publish_other(node, ticks: int) -> None:
    from std_msgs.msg import String

    force = node.create_publisher(force_message_type("vector3"), TOPICS["servo_cf"].name,
                                  TOPICS["servo_cf"].qos)
    text = node.create_publisher(String, "/custom/topic", 10)
    wait_for_subscribers((force, text))
    print("publishing", flush=True)
    for k in range(ticks):
        force.publish(force_message("vector3", [0.0, 0.0, k * 1e-3], 0.0, ""))
        text.publish(String(data=str(k)))
        time.sleep(0.001)
    for publisher in (force, text):
        publisher.wait_for_all_acked(Duration(seconds=5.0))
    print(json.dumps({TOPICS["servo_cf"].name: ticks, "/custom/topic": ticks}), flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2:] == ["other"])
