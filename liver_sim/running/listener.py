"""A listening node for the demo and the loop benchmark: keeps what the network publishes, with
the time each message arrived, for analysis after the run."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from liver_sim.base.topic_names import in_namespace, tool_topic
from liver_sim.nodes.inputs import LoopInputs
from liver_sim.realtime.rate_loop import RateLoop
from msg_defs.forces import force_from_bytes, force_message_type
from msg_defs.point_cloud import pointcloud2_to_nodes
from msg_defs.poses import pose_from_bytes
from msg_defs.skin import mesh_msg_to_arrays
from msg_defs.stamps import seconds_from_stamp, stamp_s_from_bytes
from msg_defs.topics import TOPICS, batch_qos

#: How often (Hz) the listener takes the 1 kHz and 150 Hz streams, in batches.
POLL_RATE_HZ = 200.0
#: Messages each stream keeps between two polls: 5 s of the 1 kHz commands, so that a listener starved of CPU
#: for seconds (normal priority beside real-time nodes and a busy machine) loses nothing it must measure.
HISTORY_DEPTH = 5000
#: What the listener keeps (s of each stream, counted back from its newest message): its memory is bounded
#: however long a run lasts; a longer run's figures cover its last MAX_KEPT_S.
MAX_KEPT_S = 600.0


@dataclass(frozen=True)
class NetworkSnapshot:
    """What a NetworkListener received so far. Times are seconds on the time.monotonic() scale: `*_arrival_s`
    when a message reached the listener, `*_published_s` when its publisher sent it (DDS source times, whatever
    the listener's own scheduling). Forces in N, positions in m, in the frame of their topic. Each label is one device
    side: its force commands, and the device samples and physics wrench of its namespace."""

    #: label -> (arrival_s (K,), force commands (K, 3) N), one label per force topic listened to
    forces: dict
    #: label -> publication times (K,) of those force commands
    force_published_s: dict
    #: label -> for each force command stamped with a device sample, the time from that sample's publication to the
    #: command's (K,) s (the one hop: device → force); NaN where the sample was not seen
    pose_to_force_s: dict
    #: label -> header stamps (K,) of the force commands (s, ROS time: the device sample a command was computed
    #: from, or the bridge's clock); NaN for formats without a header
    force_stamp_s: dict
    #: label -> for each force command, from its header stamp to its arrival here (K,) s: the device's sampling
    #: to the command reaching this client, as a neighbour on the rig sees it
    stamp_to_arrival_s: dict
    #: label -> arrival times (W,) and forces (W, 3) of the physics contact force on its tool (/liver/tool_wrench)
    wrench_arrival_s: dict
    wrench_n: dict
    #: label -> arrival times (P,) and stylus positions (P, 3) m, device frame, of its device (/phantom/measured_cp)
    device_arrival_s: dict
    device_position_m: dict
    #: arrival, publication and header-stamp times (F,) of /liver/nodes
    nodes_arrival_s: np.ndarray
    nodes_published_s: np.ndarray
    nodes_stamp_s: np.ndarray
    #: "node: loop" -> the newest /diagnostics key-values of each status
    diagnostics: dict
    #: (skin triangles (T, 3), rest positions (N, 3)) of the newest and of the first /liver/surface, or None
    surface: tuple | None
    initial_surface: tuple | None
    #: how many /liver/surface messages arrived (one at start, one more per tear or cut)
    surface_messages: int
    #: node positions (N, 3): the first received, the farthest from them with the same node count, the newest
    initial_nodes: np.ndarray | None
    peak_nodes: np.ndarray | None
    last_nodes: np.ndarray | None


class NetworkListener(Node):
    """Listens to the force commands, the devices' samples, the nodes, the physics wrenches, /liver/surface and
    /diagnostics.

    `force_topics` maps a label to (topic, force_output format), e.g. {'local_model': ('/phantom/servo_cf',
    'wrench_stamped')}; `namespaces` a label to the namespace of its device side ('/' by default), where its
    device samples (phantom/measured_cp) and physics wrench (liver/tool_wrench) are listened to, e.g. {'left':
    '/left'}. The force commands, device samples, nodes and physics wrenches are taken in batches by a
    POLL_RATE_HZ loop (cheaper than a callback each) and timed by DDS: `*_arrival_s` is when the message reached
    this process (the rmw's receive time, on the time.monotonic() scale). Messages are decoded in
    `snapshot()`, only those not decoded by an earlier call. `peak_nodes` are the node positions
    farthest (largest coordinate change) from the first ones received with the same node count;
    `initial_nodes` and `initial_surface` the first ones received, `surface` the newest (a tear or a
    cut changes it, and the node count with it).
    """

    def __init__(self, force_topics: dict[str, tuple[str, str]], name: str = "liver_sim_listener", context=None,
                 namespaces: dict[str, str] | None = None):
        super().__init__(name, context=context)
        self._lock = threading.Lock()
        self._monotonic_minus_wall_s = time.monotonic() - time.time()
        self._force_formats = {label: fmt for label, (_, fmt) in force_topics.items()}
        self._namespaces = {label: (namespaces or {}).get(label, "/") for label in force_topics}
        self._received = {("force", label): [] for label in force_topics}
        for namespace in set(self._namespaces.values()):
            self._received["device_pose", namespace], self._received["tool_wrench", namespace] = [], []
        self._received["nodes"] = []
        self._decoded = {key: [] for key in self._received}
        self.diagnostics: dict[str, dict] = {}
        self.initial_surface = self.surface = None
        self.surface_messages = 0
        self.initial_nodes = self.first_nodes = self.peak_nodes = self.last_nodes = None
        self._peak_displacement = -1.0
        self._polled = LoopInputs(self)
        for label, (topic, fmt) in force_topics.items():
            self._take(("force", label), force_message_type(fmt), topic, TOPICS["servo_cf"])
        for namespace in sorted(set(self._namespaces.values())):
            for key in ("measured_cp", "tool_wrench"):
                self._take(("device_pose" if key == "measured_cp" else key, namespace), TOPICS[key].type,
                           in_namespace(tool_topic(key), namespace), TOPICS[key])
        self._take("nodes", TOPICS["nodes"].type, TOPICS["nodes"].name, TOPICS["nodes"])
        self.create_subscription(TOPICS["surface"].type, TOPICS["surface"].name, self._on_surface,
                                 TOPICS["surface"].qos)
        self.create_subscription(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name, self._on_diagnostics,
                                 TOPICS["diagnostics"].qos)
        self._poller = RateLoop(POLL_RATE_HZ, lambda now: self._polled.poll(), f"{name}_poll", freeze=False)
        self._poller.start()

    def destroy_node(self) -> None:
        self._poller.stop()
        self._polled.destroy()
        super().destroy_node()

    def _take(self, key, msg_type, topic: str, row) -> None:
        """Keep every message of `topic` as (bytes, rmw info) under `key`."""
        received = self._received[key]

        def keep(data: bytes, info: dict) -> None:
            with self._lock:
                received.append((data, info))
        self._polled.subscribe(msg_type, topic, batch_qos(row, HISTORY_DEPTH), keep, raw=True, every=True)

    def _new(self, key) -> list:
        """The messages under `key` not decoded yet, taken out of the received ones (whose bytes then go): (arrival
        here s, publication s, bytes), both times as DDS stamped them, on the time.monotonic() scale. The decoded
        rows of `key` older than MAX_KEPT_S before the newest are dropped."""
        with self._lock:
            received = self._received[key]
            new = received[:]
            del received[:]
        decoded = self._decoded[key]
        if new and decoded:
            oldest = new[-1][1]["received_timestamp"] * 1e-9 + self._monotonic_minus_wall_s - MAX_KEPT_S
            cut = next((i for i, row in enumerate(decoded) if row[0] >= oldest), len(decoded))
            del decoded[:cut]
        offset = self._monotonic_minus_wall_s
        return [(info["received_timestamp"] * 1e-9 + offset, info["source_timestamp"] * 1e-9 + offset, data)
                for data, info in new]

    def _decode_forces(self, label) -> tuple:
        """(arrival_s, published_s, forces (K, 3) N, pose stamps (K,) s or NaN) of the force commands so far."""
        fmt = self._force_formats[label]
        decoded = self._decoded["force", label]
        for arrival, published, data in self._new(("force", label)):
            force = force_from_bytes(fmt, data)
            stamp = stamp_s_from_bytes(data, "WrenchStamped") if fmt == "wrench_stamped" else np.nan
            decoded.append((arrival, published, force, stamp))
        return (np.array([d[0] for d in decoded]), np.array([d[1] for d in decoded]),
                np.array([d[2] for d in decoded]).reshape(-1, 3), np.array([d[3] for d in decoded]))

    def _decode_device_poses(self, namespace: str) -> tuple:
        """(arrival_s, published_s, stamp_s, positions (K, 3) m, device frame) of the samples so far of the device in
        `namespace`."""
        decoded = self._decoded["device_pose", namespace]
        for arrival, published, data in self._new(("device_pose", namespace)):
            try:
                position, _, (sec, nanosec) = pose_from_bytes(data)
            except ValueError:
                continue  # a refused pose is the nodes' business; it has no place in the figures
            decoded.append((arrival, published, sec + nanosec * 1e-9, position))
        return tuple(np.array([d[i] for d in decoded]) for i in range(3)) + (
            np.array([d[3] for d in decoded]).reshape(-1, 3),)

    def _decode_nodes(self) -> tuple:
        """(arrival_s, published_s, stamp_s) of the node clouds so far; tracks the first, peak and last positions."""
        decoded = self._decoded["nodes"]
        for arrival, published, data in self._new("nodes"):
            message = deserialize_message(data, TOPICS["nodes"].type)
            decoded.append((arrival, published, seconds_from_stamp(message.header.stamp)))
            try:
                positions = pointcloud2_to_nodes(message)
            except ValueError as exc:
                self.get_logger().warning(f"ignored /liver/nodes message: {exc}", throttle_duration_sec=1.0)
                continue
            if self.initial_nodes is None:
                self.initial_nodes = positions
            if self.first_nodes is None or len(self.first_nodes) != len(positions):
                self.first_nodes, self._peak_displacement = positions, -1.0
            self.last_nodes = positions
            displacement = float(np.abs(positions - self.first_nodes).max())
            if displacement > self._peak_displacement:
                self._peak_displacement, self.peak_nodes = displacement, positions
        return tuple(np.array([d[i] for d in decoded]) for i in range(3))

    def _decode_wrenches(self, namespace: str) -> tuple:
        """(arrival_s, forces (K, 3) N) of the physics wrenches so far of the tool in `namespace`."""
        decoded = self._decoded["tool_wrench", namespace]
        for arrival, _, data in self._new(("tool_wrench", namespace)):
            try:
                decoded.append((arrival, force_from_bytes("wrench_stamped", data)))
            except ValueError:
                continue  # a refused wrench is the bridge's business
        return np.array([d[0] for d in decoded]), np.array([d[1] for d in decoded]).reshape(-1, 3)

    def _on_surface(self, message) -> None:
        try:
            surface = mesh_msg_to_arrays(message)
        except ValueError as exc:
            self.get_logger().warning(f"ignored /liver/surface message: {exc}")
            return
        with self._lock:
            self.surface = surface
            self.initial_surface = surface if self.initial_surface is None else self.initial_surface
            self.surface_messages += 1

    def _on_diagnostics(self, message) -> None:
        with self._lock:
            for status in message.status:
                self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def decode(self) -> None:
        """Decode what has arrived so far (its bytes go; see :meth:`_new`): called every few seconds during a
        run, so that the listener's memory stays bounded."""
        for label in self._force_formats:
            self._decode_forces(label)
        for namespace in set(self._namespaces.values()):
            self._decode_device_poses(namespace)
            self._decode_wrenches(namespace)
        self._decode_nodes()

    def snapshot(self) -> NetworkSnapshot:
        """Copies of everything received so far, as numpy arrays where that fits.

        `*_arrival_s` are when messages reached this process, `*_published_s` when their publisher sent
        them (DDS times, independent of how promptly this process runs). `pose_to_force_s[label]`: for
        each force command stamped with a device sample (of its own namespace's device), the time from that sample's
        publication to the command's (s; NaN when the sample was not seen).
        """
        decoded = {label: self._decode_forces(label) for label in self._force_formats}
        namespaces = set(self._namespaces.values())
        devices = {namespace: self._decode_device_poses(namespace) for namespace in namespaces}
        wrenches = {namespace: self._decode_wrenches(namespace) for namespace in namespaces}
        nodes_arrival, nodes_published, nodes_stamp = self._decode_nodes()
        published_by_stamp = {namespace: dict(zip(stamps.tolist(), published.tolist()))
                              for namespace, (_, published, stamps, _) in devices.items()}
        of = self._namespaces
        with self._lock:
            return NetworkSnapshot(
                forces={label: (arrival, values) for label, (arrival, _, values, _) in decoded.items()},
                force_published_s={label: published for label, (_, published, _, _) in decoded.items()},
                pose_to_force_s={label: np.array([sent - published_by_stamp[of[label]].get(stamp, np.nan)
                                                  for sent, stamp in zip(sent_s, stamps)])
                                 for label, (_, sent_s, _, stamps) in decoded.items()},
                force_stamp_s={label: stamps for label, (_, _, _, stamps) in decoded.items()},
                stamp_to_arrival_s={label: arrival - self._monotonic_minus_wall_s - stamps
                                    for label, (arrival, _, _, stamps) in decoded.items()},
                wrench_arrival_s={label: wrenches[of[label]][0] for label in of},
                wrench_n={label: wrenches[of[label]][1] for label in of},
                device_arrival_s={label: devices[of[label]][0] for label in of},
                device_position_m={label: devices[of[label]][3] for label in of},
                nodes_arrival_s=nodes_arrival,
                nodes_published_s=nodes_published,
                nodes_stamp_s=nodes_stamp,
                diagnostics={k: dict(v) for k, v in self.diagnostics.items()},
                surface=self.surface,
                initial_surface=self.initial_surface,
                surface_messages=self.surface_messages,
                initial_nodes=self.initial_nodes,
                peak_nodes=self.peak_nodes,
                last_nodes=self.last_nodes,
            )
