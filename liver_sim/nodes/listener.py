"""A listening node for the demo and the loop benchmark: keeps what the network publishes, with
the monotonic time each message arrived, for analysis after the run."""
from __future__ import annotations

import threading
import time

import numpy as np
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from msg_defs import conversions
from msg_defs.topics import TOPICS


class NetworkListener(Node):
    """Subscribes to the force commands, the physics wrench and nodes, /diagnostics and optionally the tool pose.

    `peak_nodes` are the node positions farthest (largest coordinate change) from the first ones received.

    `force_topics` maps a label to (topic, force_output format), e.g. {'local_model': ('/phantom/servo_cf',
    'wrench_stamped')}.  Force samples keep the monotonic arrival time, the age of their stamp on arrival
    (wall clock minus stamp: the bridge stamps a command with the tool pose it used) and the force.
    """

    def __init__(self, force_topics: dict[str, tuple[str, str]], name: str = "liver_sim_listener", context=None,
                 tool_pose: bool = False):
        super().__init__(name, context=context)
        self._lock = threading.Lock()
        self.forces = {label: [] for label in force_topics}
        self.wrenches, self.tool_poses, self.node_stamps = [], [], []
        self.diagnostics: dict[str, dict] = {}
        self.surface = None
        self.first_nodes = self.peak_nodes = self.last_nodes = None
        self._peak_displacement = -1.0
        self._force_formats = {label: fmt for label, (_, fmt) in force_topics.items()}
        self._decoded = {label: [] for label in force_topics}
        for label, (topic, fmt) in force_topics.items():  # 1 kHz: keep bytes, deserialise in snapshot()
            self.create_subscription(conversions.force_message_type(fmt), topic,
                                     lambda data, label=label: self._on_force(label, data),
                                     TOPICS["servo_cf"].qos, raw=True)
        self.create_subscription(TOPICS["tool_wrench"].type, TOPICS["tool_wrench"].name, self._on_wrench,
                                 TOPICS["tool_wrench"].qos)
        if tool_pose:  # 1 kHz of Python callbacks: only when asked for
            self.create_subscription(TOPICS["tool_pose"].type, TOPICS["tool_pose"].name, self._on_pose,
                                     TOPICS["tool_pose"].qos)
        self.create_subscription(TOPICS["nodes"].type, TOPICS["nodes"].name, self._on_nodes, TOPICS["nodes"].qos)
        self.create_subscription(TOPICS["surface"].type, TOPICS["surface"].name, self._on_surface,
                                 TOPICS["surface"].qos)
        self.create_subscription(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name, self._on_diagnostics,
                                 TOPICS["diagnostics"].qos)

    def _on_force(self, label, data: bytes) -> None:
        with self._lock:
            self.forces[label].append((time.monotonic(), time.time(), data))

    def _decode_forces(self, label) -> tuple:
        """(arrival_s, forces (K, 3) N, stamp age on arrival (K,) s) of the force commands so far;
        only the samples not decoded by an earlier call are deserialised."""
        fmt = self._force_formats[label]
        kind = conversions.force_message_type(fmt)
        with self._lock:
            new = self.forces[label][len(self._decoded[label]):]
        for arrival, wall, data in new:
            message = deserialize_message(data, kind)
            header = getattr(message, "header", None)
            age = wall - conversions.seconds_from_stamp(header.stamp) if header is not None else np.nan
            self._decoded[label].append((arrival, conversions.force_from_message(fmt, message), age))
        decoded = self._decoded[label]
        return (np.array([d[0] for d in decoded]), np.array([d[1] for d in decoded]).reshape(-1, 3),
                np.array([d[2] for d in decoded]))

    def _on_wrench(self, message) -> None:
        f = message.wrench.force
        with self._lock:
            self.wrenches.append((time.monotonic(), conversions.seconds_from_stamp(message.header.stamp),
                                  np.array([f.x, f.y, f.z])))

    def _on_pose(self, message) -> None:
        position, _ = conversions.pose_to_arrays(message.pose)
        with self._lock:
            self.tool_poses.append((time.monotonic(), position))

    def _on_nodes(self, message) -> None:
        try:
            positions = conversions.pointcloud2_to_nodes(message)
        except ValueError as exc:
            self.get_logger().warning(f"ignored /liver/nodes message: {exc}", throttle_duration_sec=1.0)
            return
        with self._lock:
            self.node_stamps.append((time.monotonic(), conversions.seconds_from_stamp(message.header.stamp)))
            if self.first_nodes is None or len(self.first_nodes) != len(positions):
                self.first_nodes, self._peak_displacement = positions, -1.0
            self.last_nodes = positions
            displacement = float(np.abs(positions - self.first_nodes).max())
            if displacement > self._peak_displacement:
                self._peak_displacement, self.peak_nodes = displacement, positions

    def _on_surface(self, message) -> None:
        with self._lock:
            self.surface = conversions.mesh_msg_to_arrays(message)

    def _on_diagnostics(self, message) -> None:
        with self._lock:
            for status in message.status:
                self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def snapshot(self) -> dict:
        """Copies of everything received so far, as numpy arrays where that fits."""
        decoded = {label: self._decode_forces(label) for label in self.forces}
        with self._lock:
            return {
                "forces": {label: (arrival, values) for label, (arrival, values, _) in decoded.items()},
                "force_stamp_age_s": {label: ages for label, (_, _, ages) in decoded.items()},
                "wrench_arrival_s": np.array([s[0] for s in self.wrenches]),
                "wrench_n": np.array([s[2] for s in self.wrenches]).reshape(-1, 3),
                "tool_arrival_s": np.array([s[0] for s in self.tool_poses]),
                "tool_position_m": np.array([s[1] for s in self.tool_poses]).reshape(-1, 3),
                "nodes_arrival_s": np.array([s[0] for s in self.node_stamps]),
                "nodes_stamp_s": np.array([s[1] for s in self.node_stamps]),
                "diagnostics": {k: dict(v) for k, v in self.diagnostics.items()},
                "surface": self.surface,
                "peak_nodes": self.peak_nodes,
                "last_nodes": self.last_nodes,
            }
