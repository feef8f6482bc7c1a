"""The liver_sim wire format (docs/contract.md, "Topics" and "Message encodings").

- :mod:`msg_defs.conversions`: numpy arrays ↔ ROS messages, both ways, validated (no rclpy node code);
- :mod:`msg_defs.topics`: default topic names, message types and QoS, one entry per row of the topics table.
"""
