"""DESIGN.md's topics table as data: default name, message type and QoS of each topic.

The names are defaults (nodes declare them as parameters); the QoS profile of a row suits both its
publishers and its subscribers.
"""
from __future__ import annotations

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from shape_msgs.msg import Mesh
from visualization_msgs.msg import Marker


@dataclass(frozen=True)
class Topic:
    """A topic's default name, message class and QoS. `type` is None where a parameter chooses it
    (servo_cf: `force_output`, see msg_defs.conversions.force_message_type)."""

    name: str
    type: type | None
    qos: QoSProfile


def _qos(depth: int, reliable: bool = True, transient_local: bool = False) -> QoSProfile:
    """Keep-last `depth`, reliable or best effort, transient local or volatile."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE)


TOPICS = {
    "nodes": Topic("/liver/nodes", PointCloud2, _qos(1)),
    "surface": Topic("/liver/surface", Mesh, _qos(1, transient_local=True)),
    "marker": Topic("/liver/marker", Marker, _qos(1)),
    "contact_plane": Topic("/liver/contact_plane", Marker, _qos(1)),
    "tool_wrench": Topic("/liver/tool_wrench", WrenchStamped, _qos(10)),
    "tool_pose": Topic("/tool/pose", PoseStamped, _qos(1, reliable=False)),
    "measured_cp": Topic("/phantom/measured_cp", PoseStamped, _qos(1, reliable=False)),
    "servo_cf": Topic("/phantom/servo_cf", None, _qos(1)),
    # "default" in the table: rclpy's usual keep-last 10, reliable, volatile.
    "diagnostics": Topic("/diagnostics", DiagnosticArray, _qos(10)),
}

#: Force topic of a baseline bridge (`local_model: none`) beside the normal one: the Fig. 8 comparison
#: in `liver-sim bench loop`; it drives nothing.
BASELINE_FORCE_TOPIC = "/phantom/servo_cf_without_local_model"


def batch_qos(topic: Topic, depth: int = 1000) -> QoSProfile:
    """`topic`'s reliability and durability with a keep-last `depth` history: for a subscriber that
    takes messages in batches (a listener or recorder polling every few ms) and must keep them all."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=topic.qos.reliability,
                      durability=topic.qos.durability)
