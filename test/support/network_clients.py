"""Clients the process tests watch the product's network with, as a rig would: an independent subscriber that
numbers what each writer sent (Tally), nodes started by a test with a listener beside them (Network), and waits on
conditions with a deadline that fail with what was seen."""
from __future__ import annotations

import threading
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from waiting import wait_for

from liver_sim.nodes.rcl_take import SerializedTake
from liver_sim.nodes.run import spin
from liver_sim.running.launcher import NodeProcesses
from liver_sim.running.listener import NetworkListener
from liver_sim.sessions.record import _rclpy_qos, default_topics, known_topics


def read_bag(path) -> dict:
    """{topic: [(msgtype, log time ns, deserialized message)]} of the bag at `path`, read by rosbags alone."""
    store = get_typestore(Stores.ROS2_JAZZY)
    read = {}
    with Reader(path) as reader:
        for connection, timestamp, data in reader.messages():
            read.setdefault(connection.topic, []).append(
                (connection.msgtype, timestamp, store.deserialize_cdr(data, connection.msgtype)))
    return read


class Tally:
    """An independent client: subscribes to `topics` (default: every topic a recording holds) with the contract's
    QoS in a context of its own (the ROS_DOMAIN_ID of the environment) and keeps, per writer (topic, gid hex),
    each message's publication sequence number and source time (ns, the publisher's system clock)."""

    def __init__(self, topics: list[str] | None = None):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("independent_tally", context=self.context)
        known = known_topics()
        self.takes = {}
        for topic in topics or default_topics():
            msg_class, spec = known[topic]
            subscription = self.node.create_subscription(msg_class, topic, lambda _: None,
                                                         _rclpy_qos(spec, spec.depth + 5000), raw=True)
            self.takes[topic] = SerializedTake(subscription)
        self._lock = threading.Lock()
        self.sent: dict[tuple[str, str], list[tuple[int, int]]] = {}
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop.wait(0.01):
            for topic, take in self.takes.items():
                while (message := take()) is not None:
                    with self._lock:
                        self.sent.setdefault((topic, message.gid.hex()), []).append(
                            (message.sequence, message.source_ns))

    def subscribers(self, topic: str, node_name: str) -> int:
        """How many subscriptions of node `node_name` to `topic` the ROS graph shows."""
        return sum(info.node_name == node_name for info in self.node.get_subscriptions_info_by_topic(topic))

    def count(self, topic: str) -> int:
        """Messages of `topic` seen so far, from every writer."""
        with self._lock:
            return sum(len(seen) for (t, _), seen in self.sent.items() if t == topic)

    def counts(self) -> dict[str, int]:
        with self._lock:
            totals = {}
            for (topic, _), seen in self.sent.items():
                totals[topic] = totals.get(topic, 0) + len(seen)
            return totals

    def last(self, before_ns: int | None = None) -> dict[tuple[str, str], int]:
        """{(topic, gid hex): the highest sequence number seen} of each writer, counting only messages published
        before `before_ns` (source time) when given."""
        with self._lock:
            last = {}
            for key, seen in self.sent.items():
                numbers = [sequence for sequence, source_ns in seen if before_ns is None or source_ns < before_ns]
                if numbers:
                    last[key] = max(numbers)
            return last

    def close(self, linger_s: float = 1.0):
        """Stop listening after `linger_s` (for the last acknowledged messages)."""
        time.sleep(linger_s)
        self.stop.set()
        self.thread.join()
        for take in self.takes.values():
            take.close()
        self.node.destroy_node()
        self.context.try_shutdown()


class Network:
    """Nodes started by a test, and a listener in the test process (running.listener.NetworkListener) of the force
    topics `force_topics` (label -> (topic, format); default the one device's) and each label's namespace
    (`namespaces`, NetworkPlan.namespaces)."""

    def __init__(self, log_dir, force_topics: dict | None = None, namespaces: dict | None = None):
        self.processes = NodeProcesses(log_dir)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.listener = NetworkListener(force_topics or {"local_model": ("/phantom/servo_cf", "wrench_stamped")},
                                        context=self.context, namespaces=namespaces)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.listener)
        self.thread = threading.Thread(target=spin, args=(self.executor, self.context), daemon=True)
        self.thread.start()

    def forces_since(self, t0, label: str = "local_model"):
        """The `label` force commands (K, 3) N received at or after `t0` (time.monotonic())."""
        arrival, forces = self.listener.snapshot().forces[label]
        return forces[arrival >= t0]

    def wait_for(self, condition, timeout_s, what):
        wait_for(condition, timeout_s, what, lambda: f"exited {self.processes.failed()}; logs in "
                                                    f"{self.processes.log_dir}")

    def close(self):
        self.processes.stop()
        self.context.try_shutdown()
        self.thread.join(timeout=2.0)
        self.listener.destroy_node()
