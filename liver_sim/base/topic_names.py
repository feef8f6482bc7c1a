"""Default topic names of the topics table (docs/contract.md, "Topics") and the force command formats, as plain
strings: parameter tables declare them without importing a ROS message package. msg_defs.topics adds each
topic's message type and QoS.

A tool's topics and its device's (TOOL_TOPICS) are relative names by default (`tool_topic`): a node started in a
namespace (`__ns:=/left`) resolves them under it (/left/tool/pose, /left/phantom/servo_cf, …), a node in the root
namespace to the absolute names of TOPIC_NAMES, as before there were namespaces. The physics resolves each of its
tools' topics in the tool's namespace the same way (`in_namespace`, `tool_namespace`)."""
import re

#: Default name of each topic, by the key msg_defs.topics.TOPICS uses.
TOPIC_NAMES = {
    "nodes": "/liver/nodes",
    "surface": "/liver/surface",
    "marker": "/liver/marker",
    "contact_plane": "/liver/contact_plane",
    "tool_wrench": "/liver/tool_wrench",
    "tool_pose": "/tool/pose",
    "measured_cp": "/phantom/measured_cp",
    "servo_cf": "/phantom/servo_cf",
    "device_map": "/tool/device_map",
    "diagnostics": "/diagnostics",
}

#: The topics of one tool and its device, by TOPIC_NAMES key: one set per tool, in the tool's namespace.
TOOL_TOPICS = ("tool_pose", "contact_plane", "tool_wrench", "measured_cp", "servo_cf", "device_map")
#: What a tool's name may be: a ROS name token (it names the tool's namespace and prefixes its parameters).
TOOL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def tool_topic(key: str) -> str:
    """The default name of a tool topic (TOOL_TOPICS): relative, resolved in the node's namespace."""
    return TOPIC_NAMES[key].lstrip("/")


def tool_namespace(tool: str) -> str:
    """The namespace of the tool named `tool` ('': the root namespace)."""
    return f"/{tool}" if tool else "/"


def in_namespace(name: str, namespace: str) -> str:
    """Topic `name` resolved in `namespace` as ROS resolves it: an absolute name stays, a relative one goes under the
    namespace."""
    return name if name.startswith("/") else f"{namespace.rstrip('/')}/{name}"


#: Force topic of a baseline bridge (`local_model: none`) beside the normal one: the Fig. 8 comparison
#: in `liver-sim bench loop`; it drives nothing.
BASELINE_FORCE_TOPIC = "/phantom/servo_cf_without_local_model"

#: Message formats of a force command (`force_output`): msg_defs.forces.force_message_type gives each class.
FORCE_OUTPUT_FORMATS = ("wrench_stamped", "wrench", "vector3", "float64_array", "omni_feedback")
