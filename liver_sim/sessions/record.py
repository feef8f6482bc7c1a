"""`liver-sim record`: serialized (raw) subscriptions to the product's topics, written to a rosbag2 bag.

No executor: a loop takes every waiting message of every subscription each DRAIN_PERIOD_S and writes
them in order of arrival, each logged at its receive time (the rmw's reception timestamp).  The
history of each subscription (HISTORY_DEPTH) holds several seconds at 1 kHz, so a slow write never
drops a message; the bag notes the deepest backlog seen.  SIGINT or SIGTERM ends the recording after
a last drain and closes the bag (metadata.yaml included).
"""
from __future__ import annotations

import importlib
import signal
import threading
import time
from pathlib import Path

from liver_sim.sessions.bag import BagWriter, QosSpec

RECORDER_NODE = "liver_sim_recorder"
#: Messages kept per subscription between two drains: 2 s at 1 kHz, 100 drain periods.
HISTORY_DEPTH = 2000
DRAIN_PERIOD_S = 0.02
#: How often (s) topics of unknown type are looked up in the ROS graph.
DISCOVERY_PERIOD_S = 0.5
PROGRESS_PERIOD_S = 5.0


def default_topics(marker: bool = False) -> list[str]:
    """The topics of docs/contract.md (and the Fig. 8 baseline force); /liver/marker only when asked for."""
    from msg_defs.topics import BASELINE_FORCE_TOPIC, TOPICS

    names = [t.name for key, t in TOPICS.items() if marker or key != "marker"]
    return names + [BASELINE_FORCE_TOPIC]


def known_topics() -> dict:
    """{name: (message class, QosSpec)} of the product's topics; force commands as the contract's default
    WrenchStamped (`force_output: wrench_stamped`)."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from msg_defs.topics import BASELINE_FORCE_TOPIC, TOPICS

    known = {}
    for topic in TOPICS.values():
        spec = QosSpec(topic.qos.reliability == ReliabilityPolicy.RELIABLE,
                       topic.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL, topic.qos.depth)
        known[topic.name] = (topic.type or WrenchStamped, spec)
    known[BASELINE_FORCE_TOPIC] = (WrenchStamped, known[TOPICS["servo_cf"].name][1])
    return known


def message_class(type_name: str):
    """The Python message class of 'pkg/msg/Name', or ValueError."""
    package, _, name = type_name.partition("/msg/")
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError, ValueError):
        raise ValueError(f"message type {type_name!r} is not installed") from None


def type_name(msg_class) -> str:
    """'pkg/msg/Name' of a message class."""
    return f"{msg_class.__module__.split('.')[0]}/msg/{msg_class.__name__}"


def _rclpy_qos(spec: QosSpec, depth: int):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE)


def offered_qos(node, topic: str) -> QosSpec | None:
    """The QoS the topic's publishers offer (reliable/transient local only if all of them are), or None."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    publishers = node.get_publishers_info_by_topic(topic)
    if not publishers:
        return None
    return QosSpec(all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers),
                   all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers),
                   max(p.qos_profile.depth for p in publishers) or 10)


class Recorder:
    """Raw subscriptions of `topics` on a hidden node, drained into `writer` by `drain()`.

    Product topics are subscribed at once with their QoS of docs/contract.md (deep history); other topics once the
    graph shows their type, with the QoS their publishers offer.
    """

    def __init__(self, writer: BagWriter, topics: list[str], context, progress=print):
        import rclpy

        self.writer = writer
        self.progress = progress
        self.node = rclpy.create_node(RECORDER_NODE, context=context, start_parameter_services=False,
                                      enable_rosout=False)
        self._subscriptions = []  # (topic, type name, QosSpec, subscription)
        self._pending = []
        self.max_backlog = 0
        known = known_topics()
        for topic in topics:
            if topic in known:
                msg_class, spec = known[topic]
                self._subscribe(topic, msg_class, spec)
            else:
                self._pending.append(topic)
        self._next_discovery = 0.0
        self._unknown = set()

    def _subscribe(self, topic: str, msg_class, spec: QosSpec) -> None:
        subscription = self.node.create_subscription(msg_class, topic, lambda _: None,
                                                     _rclpy_qos(spec, HISTORY_DEPTH), raw=True)
        self._subscriptions.append((topic, type_name(msg_class), spec, subscription))

    def discover(self) -> None:
        """Subscribe to the requested topics once a publisher shows their type, and re-subscribe a topic
        published with another type than expected (e.g. servo_cf of a bridge with another force_output)."""
        for topic in list(self._pending):
            if self._try_subscribe(topic):
                self._pending.remove(topic)
        for entry in list(self._subscriptions):
            topic, name, _, subscription = entry
            published = {p.topic_type for p in self.node.get_publishers_info_by_topic(topic)}
            if published and name not in published:
                self.node.destroy_subscription(subscription)
                self._subscriptions.remove(entry)
                if not self._try_subscribe(topic):
                    self._pending.append(topic)

    def _try_subscribe(self, topic: str) -> bool:
        """Subscribe to `topic` with its publishers' type and QoS; False while it has no publisher."""
        publishers = self.node.get_publishers_info_by_topic(topic)
        if not publishers:
            return False
        kind = publishers[0].topic_type
        try:
            msg_class = message_class(kind)
        except ValueError as exc:
            if topic not in self._unknown:
                self._unknown.add(topic)
                self.progress(f"warning: {topic} not recorded: {exc}")
            return False
        self._subscribe(topic, msg_class, offered_qos(self.node, topic))
        self.progress(f"recording {topic} ({kind})")
        return True

    def drain(self) -> int:
        """Take every waiting message and write them in order of reception; return how many."""
        taken = []
        for topic, name, spec, subscription in self._subscriptions:
            count = 0
            with subscription.handle:
                while (message := subscription.handle.take_message(subscription.msg_type, True)) is not None:
                    data, info = message
                    taken.append((info.get("received_timestamp") or time.time_ns(), topic, name, spec, data))
                    count += 1
            self.max_backlog = max(self.max_backlog, count)
        taken.sort(key=lambda item: item[0])
        for received, topic, name, spec, data in taken:
            self.writer.write(topic, name, received, data, spec)
        return len(taken)

    def run(self, stop: threading.Event, duration_s: float | None = None) -> None:
        """Drain every DRAIN_PERIOD_S until `stop` is set (or `duration_s` has passed), then once more."""
        start = time.monotonic()
        next_drain = next_progress = start
        while not stop.is_set() and (duration_s is None or time.monotonic() - start < duration_s):
            now = time.monotonic()
            if now >= self._next_discovery:
                self.discover()
                self._next_discovery = now + DISCOVERY_PERIOD_S
            self.drain()
            if now >= next_progress + PROGRESS_PERIOD_S:
                next_progress = now
                self.progress(f"  {now - start:6.1f} s: {sum(self.writer.counts.values())} messages")
            next_drain += DRAIN_PERIOD_S
            stop.wait(max(0.0, next_drain - time.monotonic()))
        self.drain()

    def destroy(self) -> None:
        self.node.destroy_node()


def run_record(out: Path, topics: list[str], storage: str = "mcap", duration_s: float | None = None,
               progress=print) -> dict[str, int]:
    """Record `topics` into a new bag at `out` until SIGINT/SIGTERM (or `duration_s`); return the counts.

    metadata.yaml's custom_data gets the recorder's CPU and wall time (s) and its deepest backlog.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    cpu0, wall0 = time.process_time(), time.monotonic()
    try:
        with BagWriter(out, storage) as writer:
            recorder = Recorder(writer, topics, context, progress)
            progress(f"recording to {out} ({storage}): {', '.join(topics)}; stop with Ctrl-C")
            try:
                recorder.run(stop, duration_s)
            finally:
                recorder.destroy()
                writer.set_custom_data("recorder_cpu_s", f"{time.process_time() - cpu0:.3f}")
                writer.set_custom_data("recorder_wall_s", f"{time.monotonic() - wall0:.3f}")
                writer.set_custom_data("recorder_history_depth", HISTORY_DEPTH)
                writer.set_custom_data("recorder_max_backlog", recorder.max_backlog)
            counts = dict(writer.counts)
    finally:
        context.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if recorder.max_backlog >= HISTORY_DEPTH:
        progress(f"warning: a subscription's history ({HISTORY_DEPTH}) filled up between two writes: "
                 "messages may have been lost")
    progress(f"wrote {out}: " + (", ".join(f"{t} {n}" for t, n in sorted(counts.items())) or "no messages"))
    return counts
