"""The topics table of docs/contract.md as data: default name, message type and QoS of each topic.

The names are defaults (nodes declare them as parameters); the QoS profile of a row suits both its
publishers and its subscribers.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from shape_msgs.msg import Mesh
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker

from liver_sim.base.topic_names import TOPIC_NAMES


@dataclass(frozen=True)
class Topic:
    """A topic's default name, message class and QoS: keep-last `depth`, reliable or best effort,
    transient local or volatile. `type` is None where a parameter chooses it (servo_cf: `force_output`,
    see msg_defs.forces.force_message_type)."""

    name: str
    type: type | None
    depth: int
    reliable: bool = True
    transient_local: bool = False

    @cached_property
    def qos(self):
        """The rclpy QoSProfile (rclpy is imported here, so that the names and types need no rclpy)."""

        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.depth,
                          reliability=ReliabilityPolicy.RELIABLE if self.reliable else ReliabilityPolicy.BEST_EFFORT,
                          durability=(DurabilityPolicy.TRANSIENT_LOCAL if self.transient_local
                                      else DurabilityPolicy.VOLATILE))


#: Seconds of messages a reliable publisher keeps, transient local, for a reader that fell behind (a
#: recorder starved for a moment, a viewer) or matched it late: Fast DDS re-announces a participant every
#: 3 s, so a process whose first announcements were missed at a busy start-up is matched 2-3 s late (a
#: recorder lost the first 20 mesh frames of a demo with 2 s of them kept). Its history depth is this at the
#: topic's rate. Best-effort topics resend nothing, so their depth stays 1. Memory: depth × message size per
#: publisher (docs/contract.md).
CATCH_UP_S = 5.0


def catch_up_depth(rate_hz: float, seconds: float = CATCH_UP_S) -> int:
    """History depth of a reliable publisher at `rate_hz` (its default rate) that keeps `seconds` of messages."""
    return max(1, round(seconds * rate_hz))


TOPICS = {
    "nodes": Topic(TOPIC_NAMES["nodes"], PointCloud2, catch_up_depth(150.0), transient_local=True),
    # at start and after a tear or cut, at most one per 150 Hz frame
    "surface": Topic(TOPIC_NAMES["surface"], Mesh, catch_up_depth(150.0), transient_local=True),
    "marker": Topic(TOPIC_NAMES["marker"], Marker, catch_up_depth(30.0), transient_local=True),
    "contact_plane": Topic(TOPIC_NAMES["contact_plane"], Marker, catch_up_depth(150.0), transient_local=True),
    "tool_wrench": Topic(TOPIC_NAMES["tool_wrench"], WrenchStamped, catch_up_depth(150.0), transient_local=True),
    "tool_pose": Topic(TOPIC_NAMES["tool_pose"], PoseStamped, 1, reliable=False),
    "measured_cp": Topic(TOPIC_NAMES["measured_cp"], PoseStamped, 1, reliable=False),
    "servo_cf": Topic(TOPIC_NAMES["servo_cf"], None, catch_up_depth(1000.0), transient_local=True),
    # the device map liver_tool uses, for the bridge (msg_defs.device_map.device_map_message): published once
    "device_map": Topic(TOPIC_NAMES["device_map"], Float64MultiArray, 1, transient_local=True),
    # 1 Hz per node
    "diagnostics": Topic(TOPIC_NAMES["diagnostics"], DiagnosticArray, catch_up_depth(1.0), transient_local=True),
}

def batch_qos(topic: Topic, depth: int = 1000):
    """`topic`'s reliability and durability with a keep-last `depth` history (a QoSProfile): for a subscriber
    that takes messages in batches (a listener or recorder polling every few ms) and must keep them all."""
    return Topic(topic.name, topic.type, depth, topic.reliable, topic.transient_local).qos


def loop_input_qos(topic: Topic, depth: int = 1):
    """The QoS a node takes an input with (the tool pose, the local model, the physics wrench, the device's
    samples): best effort, volatile, keep last `depth` (the newest message only by default; deeper for a reader
    that judges every sample by its writer, so that other writers' samples cannot displace its source's before it
    reads them). It matches every publisher, one with ROS's default QoS (reliable, volatile) included, and a
    publisher's transient-local history is never delivered when it (re)matches: an old local model received now
    would look fresh to the watchdog."""
    return Topic(topic.name, topic.type, depth, reliable=False, transient_local=False).qos


def latched_reader_qos(topic: Topic):
    """The QoS a node reads a latched input with (the device map): reliable, transient local, keep all. A keep-last
    reader's history is replaced by whatever writer sends most, so a flood of foreign samples would displace the
    source's one latched sample; a keep-all reader keeps every sample until it is taken (a full reader holds back
    the reliable writers' next ones instead of dropping)."""
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def device_command_qos(topic: Topic):
    """The QoS a device (driver or phantom_sim) subscribes to force commands with: `topic`'s reliability and
    depth, but VOLATILE. The bridge's publisher keeps transient-local history for a recorder that matches
    late; a device must never receive that history, since an old force command replayed on joining would push
    the hand. Drivers subscribing with ROS's default QoS (volatile) get none (docs/haptic-safety.md)."""
    return Topic(topic.name, topic.type, topic.depth, topic.reliable, transient_local=False).qos

