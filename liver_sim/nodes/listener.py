"""A listening node for the demo and the loop benchmark: keeps what the network publishes, with
the monotonic time each message arrived, for analysis after the run."""
from __future__ import annotations

import threading
import time

import numpy as np
from rclpy.node import Node

from msg_defs import conversions
from msg_defs.topics import TOPICS


class NetworkListener(Node):
    """Subscribes to the force commands, the physics wrench and nodes, /diagnostics and optionally the tool pose.

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
        self.peak_nodes = None
        self.last_nodes = None
        self._peak_norm = -1.0
        for label, (topic, fmt) in force_topics.items():
            self.create_subscription(conversions.force_message_type(fmt), topic,
                                     lambda msg, label=label, fmt=fmt: self._on_force(label, fmt, msg),
                                     TOPICS["servo_cf"].qos)
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

    def _on_force(self, label, fmt, message) -> None:
        force = conversions.force_from_message(fmt, message)
        header = getattr(message, "header", None)
        stamp = conversions.seconds_from_stamp(header.stamp) if header is not None else np.nan
        with self._lock:
            self.forces[label].append((time.monotonic(), time.time() - stamp, force))

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
            self.last_nodes = positions
            force = np.linalg.norm(self.wrenches[-1][2]) if self.wrenches else 0.0
            if force > self._peak_norm:
                self._peak_norm, self.peak_nodes = force, positions

    def _on_surface(self, message) -> None:
        with self._lock:
            self.surface = conversions.mesh_msg_to_arrays(message)

    def _on_diagnostics(self, message) -> None:
        with self._lock:
            for status in message.status:
                self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def snapshot(self) -> dict:
        """Copies of everything received so far, as numpy arrays where that fits."""
        with self._lock:
            return {
                "forces": {label: (np.array([s[0] for s in samples]), np.array([s[2] for s in samples]).reshape(-1, 3))
                           for label, samples in self.forces.items()},
                "force_stamp_age_s": {label: np.array([s[1] for s in samples]) for label, samples in self.forces.items()},
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
