"""`liver-sim record`: serialized (raw) subscriptions to the product's topics, written to a rosbag2 bag.

No executor: a loop takes every waiting message of every subscription each DRAIN_PERIOD_S and writes
them in order of arrival, each logged at its receive time (the rmw's reception timestamp).  The
history of each subscription (HISTORY_DEPTH) holds several seconds at 1 kHz, so a slow write never
drops a message; the bag notes the deepest backlog seen.  Every message is taken with its writer's GID
and publication sequence number (nodes.rcl_take), so every message lost to the recording is counted
(sessions.gaps) into metadata.yaml's custom_data; a recording that lost messages of a reliable topic, or
whose history overflowed, ends with EXIT_LOST.
`ready:` is printed once the subscriptions exist and have matched the publishers already in the graph:
from then on nothing is lost uncounted.  SIGINT or SIGTERM ends the recording after a last drain and
closes the bag (metadata.yaml included).
"""
from __future__ import annotations

import importlib
import time
from pathlib import Path

import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.process_settings import cli_command_line, set_realtime_priority
from liver_sim.base.stop_request import StopRequest, stop_on_signals
from liver_sim.base.topic_names import BASELINE_FORCE_TOPIC, TOOL_TOPICS, in_namespace, tool_namespace, tool_topic
from liver_sim.nodes.rcl_take import SerializedTake
from liver_sim.sessions.bag import BagWriter, QosSpec
from liver_sim.sessions.gaps import SequenceGaps
from msg_defs.topics import TOPICS

RECORDER_NODE = "liver_sim_recorder"
#: Messages kept per subscription between two drains beyond the publishers' own history depth (which a
#: late match delivers at once): 2 s at 1 kHz, 100 drain periods.
HISTORY_DEPTH = 2000
DRAIN_PERIOD_S = 0.02
#: How often (s) topics of unknown type are looked up in the ROS graph.
DISCOVERY_PERIOD_S = 0.5
PROGRESS_PERIOD_S = 5.0
#: How often (s) what was recorded goes into the storage file (BagWriter.flush): a killed recorder loses at
#: most this much, and `liver-sim bag repair` gets the rest back.
FLUSH_PERIOD_S = 1.0
#: How long (s) the recorder waits for its subscriptions to match the publishers the graph already shows.
MATCH_TIMEOUT_S = 10.0
#: The line `liver-sim record` prints when it records everything published from then on.
READY = "ready:"
#: Exit status of `liver-sim record` when messages were lost (the bag is complete and says how many).
EXIT_LOST = 3
#: SCHED_FIFO priority of the recorder (`--realtime-priority`): below the nodes' (60-80), so it never delays
#: a loop, and above every normally scheduled process, so a busy desktop (RViz, a browser, a build) cannot
#: starve its drain until a subscription's history overflows (seen: 2 s without a drain beside a spinning
#: process at normal priority).
REALTIME_PRIORITY = 20


#: A tool's topics beside TOOL_TOPICS: the Fig. 8 baseline force, relative.
BASELINE_TOOL_TOPIC = BASELINE_FORCE_TOPIC.lstrip("/")


def default_topics(marker: bool = False, tools=("",)) -> list[str]:
    """The topics of docs/contract.md (and the Fig. 8 baseline force), each tool's (TOOL_TOPICS and the baseline)
    in the namespace of each of `tools` (default: one tool in the root namespace); /liver/marker only when asked
    for."""

    names = []
    for key, topic in TOPICS.items():
        if key in TOOL_TOPICS:
            names += [in_namespace(tool_topic(key), tool_namespace(tool)) for tool in tools]
        elif marker or key != "marker":
            names.append(topic.name)
    return names + [in_namespace(BASELINE_TOOL_TOPIC, tool_namespace(tool)) for tool in tools]


def recorder_command(out: Path, storage: str = "mcap", tools=("",)) -> list[str]:
    """The command line of `liver-sim record` into `out`, of `tools`' topics (default_topics)."""
    named = [tool for tool in tools if tool]
    return cli_command_line("record", "--out", str(out), "--storage", storage,
                            *(["--tools", *named] if named else []))


def known_topics() -> dict:
    """{name: (message class, QosSpec)} of the product's topics; force commands as the contract's default
    WrenchStamped (`force_output: wrench_stamped`)."""

    known = {}
    for topic in TOPICS.values():
        spec = QosSpec(topic.qos.reliability == ReliabilityPolicy.RELIABLE,
                       topic.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL, topic.qos.depth)
        known[topic.name] = (topic.type or WrenchStamped, spec)
    known[BASELINE_FORCE_TOPIC] = (WrenchStamped, known[TOPICS["servo_cf"].name][1])
    return known


def known_topic(name: str) -> tuple | None:
    """(message class, QosSpec) of a product topic (known_topics), a tool's in any namespace included
    (/left/phantom/servo_cf as /phantom/servo_cf); None for another topic."""

    known = known_topics()
    if name in known:
        return known[name]
    for relative in [tool_topic(key) for key in TOOL_TOPICS] + [BASELINE_TOOL_TOPIC]:
        if name.endswith("/" + relative):
            return known["/" + relative]
    return None


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
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local
                                  else DurabilityPolicy.VOLATILE))


def offered_qos(node, topic: str) -> QosSpec | None:
    """The QoS the topic's publishers offer (reliable/transient local only if all of them are), or None."""

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
        self.writer = writer
        self.progress = progress
        self.node = rclpy.create_node(RECORDER_NODE, context=context, start_parameter_services=False,
                                      enable_rosout=False)
        self._subscriptions = []  # (topic, type name, QosSpec, subscription, SerializedTake)
        self._pending = []
        self.max_backlog = 0
        self.overflowed: list[str] = []
        self.gaps = SequenceGaps()
        self._writer_nodes: dict[bytes, str] = {}
        for topic in topics:
            if (product := known_topic(topic)) is not None:
                self._subscribe(topic, *product)
            else:
                self._pending.append(topic)
        self._next_discovery = 0.0
        self._unknown = set()

    def _subscribe(self, topic: str, msg_class, spec: QosSpec) -> None:
        subscription = self.node.create_subscription(msg_class, topic, lambda _: None,
                                                     _rclpy_qos(spec, spec.depth + HISTORY_DEPTH), raw=True)
        self._subscriptions.append((topic, type_name(msg_class), spec, subscription, SerializedTake(subscription)))

    def wait_until_matched(self, timeout_s: float = MATCH_TIMEOUT_S) -> int:
        """Until every subscription has matched the publishers the graph shows for its topic (at most
        `timeout_s`); those writers count as already publishing. Returns how many publishers matched."""
        deadline = time.monotonic() + timeout_s
        while True:
            shown = {topic: self.node.get_publishers_info_by_topic(topic) for topic, *_ in self._subscriptions}
            if all(sub.get_publisher_count() >= len(shown[topic]) for topic, _, _, sub, _ in self._subscriptions) \
                    or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        for topic, publishers in shown.items():
            self.gaps.already_publishing(topic, (bytes(p.endpoint_gid) for p in publishers))
        return sum(sub.get_publisher_count() for *_, sub, _ in self._subscriptions)

    @property
    def subscribed(self) -> list[str]:
        """The topics subscribed so far."""
        return [topic for topic, *_ in self._subscriptions]

    def _writer_node(self, topic: str, gid: bytes) -> str:
        """The name of the node whose writer has `gid`, from the graph ('' once it is gone)."""
        if gid not in self._writer_nodes:
            for publisher in self.node.get_publishers_info_by_topic(topic):
                self._writer_nodes[bytes(publisher.endpoint_gid)] = publisher.node_name
        return self._writer_nodes.get(gid, "")

    def discover(self) -> None:
        """Subscribe to the requested topics once a publisher shows their type, and re-subscribe a topic
        published with another type than expected (e.g. servo_cf of a bridge with another force_output)."""
        for topic in list(self._pending):
            if self._try_subscribe(topic):
                self._pending.remove(topic)
        for entry in list(self._subscriptions):
            topic, name, _, subscription, take = entry
            published = {p.topic_type for p in self.node.get_publishers_info_by_topic(topic)}
            if published and name not in published:
                take.close()
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
        self.gaps.already_publishing(topic, (bytes(p.endpoint_gid) for p in publishers))
        self.progress(f"recording {topic} ({kind})")
        return True

    def drain(self) -> int:
        """Take every waiting message and write them in order of reception; return how many."""
        taken = []
        for topic, name, spec, _, take in self._subscriptions:
            count = 0
            while (message := take()) is not None:
                self.gaps.add(topic, message.gid, message.sequence, self._writer_node(topic, message.gid),
                              message.source_ns)
                taken.append((message.received_ns or time.time_ns(), topic, name, spec, message.data))
                count += 1
            self.max_backlog = max(self.max_backlog, count)
            if count >= spec.depth + HISTORY_DEPTH and topic not in self.overflowed:
                self.overflowed.append(topic)
        taken.sort(key=lambda item: item[0])
        for received, topic, name, spec, data in taken:
            self.writer.write(topic, name, received, data, spec)
        return len(taken)

    def run(self, stop: StopRequest, duration_s: float | None = None) -> None:
        """Drain every DRAIN_PERIOD_S until `stop` is set (or `duration_s` has passed), then once more."""
        start = time.monotonic()
        next_drain = next_progress = next_flush = start
        while not stop.is_set() and (duration_s is None or time.monotonic() - start < duration_s):
            now = time.monotonic()
            if now >= self._next_discovery:
                self.discover()
                self._next_discovery = now + DISCOVERY_PERIOD_S
            self.drain()
            if now >= next_flush + FLUSH_PERIOD_S:
                next_flush = now
                self.writer.flush()
            if now >= next_progress + PROGRESS_PERIOD_S:
                next_progress = now
                self.progress(f"  {now - start:6.1f} s: {sum(self.writer.counts.values())} messages")
            next_drain += DRAIN_PERIOD_S
            stop.wait(max(0.0, next_drain - time.monotonic()))
        self.drain()

    def failures(self) -> str:
        """What this recording lost that it must not: any message of a reliable topic published after `ready` —
        between two it received (the publishers keep history for a reader that fell behind) or, of a writer
        that appeared after `ready`, before the first it received (`before_match`: its transient-local history
        covers the time discovery takes) — or a subscription's history filled up between two drains.
        Best-effort messages dropped on the way are counted in the metadata and the report, not a failure.
        '' when none."""
        reliable = {topic for topic, _, spec, _, _ in self._subscriptions if spec.reliable}
        lost: dict[str, list[int]] = {}
        for writer in self.gaps.writers.values():
            if writer.topic in reliable and writer.lost:
                counts = lost.setdefault(writer.topic, [0, 0])
                counts[0] += writer.lost
                counts[1] += writer.before_match
        reasons = [f"{n} message(s) of reliable {t} lost" + (f" ({early} before its writer matched)" if early else "")
                   for t, (n, early) in sorted(lost.items())]
        if self.overflowed:
            reasons.append(f"the history of {', '.join(self.overflowed)} filled up between two drains")
        return "; ".join(reasons)

    def destroy(self) -> None:
        for *_, take in self._subscriptions:
            take.close()
        self.node.destroy_node()


def run_record(out: Path, topics: list[str], storage: str = "mcap", duration_s: float | None = None,
               progress=print, realtime_priority: int = REALTIME_PRIORITY) -> tuple[dict[str, int], int]:
    """Record `topics` into a new bag at `out` until SIGINT/SIGTERM (or `duration_s`); return the counts per
    topic and whether the recording failed (Recorder.failures: it lost what it must not).  Its
    drain loop and its DDS threads run SCHED_FIFO at `realtime_priority` (0: as they are; refused: a warning, normal
    scheduling), below the nodes' loops.

    metadata.yaml's custom_data gets the recorder's CPU and wall time (s), its history depth and deepest
    backlog, and the lost messages (SequenceGaps.custom_data).
    """

    # before rclpy starts its threads: they inherit it. The recorder's DDS threads run real-time too, below the
    # nodes: with them at normal priority, a recorder beside the closed loop and two core-bound processes received
    # the physics' last two /diagnostics only after the node had gone, and lost them.
    refused = set_realtime_priority(realtime_priority)
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    cpu0, wall0 = time.process_time(), time.monotonic()
    try:
        with stop_on_signals() as stop, BagWriter(out, storage) as writer:
            recorder = Recorder(writer, topics, context, progress)
            progress(f"recording to {out} ({storage}): {', '.join(topics)}; stop with Ctrl-C")
            if refused:
                progress(f"warning: {refused}")
            try:
                matched = recorder.wait_until_matched()
                recorder.gaps.began_ns = time.time_ns()
                progress(f"{READY} {len(recorder.subscribed)} topics subscribed, {matched} publishers matched")
                recorder.run(stop, duration_s)
            finally:
                recorder.destroy()
                writer.set_custom_data("recorder_cpu_s", f"{time.process_time() - cpu0:.3f}")
                writer.set_custom_data("recorder_wall_s", f"{time.monotonic() - wall0:.3f}")
                writer.set_custom_data("recorder_history_depth", HISTORY_DEPTH)
                writer.set_custom_data("recorder_max_backlog", recorder.max_backlog)
                for key, value in recorder.gaps.custom_data().items():
                    writer.set_custom_data(key, value)
            counts = dict(writer.counts)
    finally:
        context.try_shutdown()
    progress(f"wrote {out}: " + (", ".join(f"{t} {n}" for t, n in sorted(counts.items())) or "no messages"))
    lost = recorder.gaps.lost_by_topic()
    progress(f"lost: {recorder.gaps.lost}" + "".join(f", {t} {n}" for t, n in sorted(lost.items()) if n)
             + (f" (per writer: custom_data 'writers' of {out / 'metadata.yaml'})" if recorder.gaps.lost else ""))
    failed = recorder.failures()
    if failed:
        progress(f"error: {failed}")
    return counts, bool(failed)
