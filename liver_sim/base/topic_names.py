"""Default topic names of the topics table (docs/contract.md, "Topics") and the force command formats, as plain
strings: parameter tables declare them without importing a ROS message package. msg_defs.topics adds each
topic's message type and QoS."""

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

#: Force topic of a baseline bridge (`local_model: none`) beside the normal one: the Fig. 8 comparison
#: in `liver-sim bench loop`; it drives nothing.
BASELINE_FORCE_TOPIC = "/phantom/servo_cf_without_local_model"

#: Message formats of a force command (`force_output`): msg_defs.forces.force_message_type gives each class.
FORCE_OUTPUT_FORMATS = ("wrench_stamped", "wrench", "vector3", "float64_array", "omni_feedback")
