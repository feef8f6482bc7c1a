"""The liver_sim wire format (docs/contract.md, "Topics" and "Message encodings").

numpy ↔ ROS messages, both ways, validated (no rclpy node code), one module per kind of message. SI units:
metres, seconds, newtons. A `stamp` argument is a builtin_interfaces/Time or a time in seconds (float).
Builders refuse non-finite input with a ValueError naming the argument, so no NaN or inf reaches the wire;
readers refuse a malformed message with a ValueError naming the field. Bulk arrays travel as numpy bytes;
only point lists (Marker, Mesh) are built point by point, because rosidl Python messages hold nested
messages as Python objects.

- :mod:`msg_defs.poses`: tool poses; :mod:`msg_defs.forces`: force commands and the tool wrench;
- :mod:`msg_defs.local_model`: the local model's Marker; :mod:`msg_defs.device_map`: the device → liver map;
- :mod:`msg_defs.point_cloud`: node positions; :mod:`msg_defs.skin`: the skin's Mesh and Marker;
- :mod:`msg_defs.stamps`: times and headers; :mod:`msg_defs.finite`: the checks of every value;
- :mod:`msg_defs.cdr`: the 1 kHz messages as bytes; :mod:`msg_defs.topics`: default topic names, message
  types and QoS, one entry per row of the topics table.
"""
