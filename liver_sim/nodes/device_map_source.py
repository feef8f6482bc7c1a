"""Which device map a bridge may take: each map sample is judged by the writer that sent it.

A bridge takes the device map only from one node, `source_node` (its parameter `device_map_node`, default
`liver_tool`: a relative name is the node of that name in the bridge's own namespace), through a
haptic_bridge.sources.WriterGate as every input of the force loop: the writer of that node the graph shows first is
pinned until it leaves the graph, and

- from the accepted writer: decoded and handed on (`on_map`); one that does not decode is refused from the source
  (`on_refused(reason, True)`: the bridge then renders zero until the source sends a good one);
- from any other node, good or bad: refused (`on_refused(reason, False)`), and nothing else changes;
- while two nodes bear the source's name: the map is withdrawn (`on_refused("two nodes named …", True)`) and the
  newest sample of each namesake kept; once one has gone, the accepted writer's kept map is judged again;
- from a writer the graph does not name (yet): its newest sample kept, and judged at each poll once the graph names
  it; a writer still unnamed after `writer_wait_s` — one that published and left before discovery named it — is refused.

The subscription is reliable, transient local (the map is latched) and keep-all, so that no flood of foreign maps
can displace the source's one sample before it is read; it belongs to a hidden node no executor spins:
:meth:`DeviceMapSource.poll`, from a timer of the owner's executor every `poll_s`, takes the samples.
"""
from __future__ import annotations

import time

import rclpy
from rclpy.serialization import deserialize_message

from haptic_bridge.sources import ACCEPT, UNKNOWN, WriterGate
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.nodes.rcl_take import SerializedTake, Taken
from liver_sim.nodes.source_graph import source_node, update_gates
from msg_defs.device_map import device_map_from_message
from msg_defs.topics import TOPICS, latched_reader_qos

#: How often (s) the map subscription is read and its undecided samples judged again.
MAP_POLL_S = 0.1
#: How long (s) a sample waits for the graph to name its writer: longer than a participant announcement period
#: (3 s) with a lost first announcement on a busy machine.
MAP_WRITER_WAIT_S = 5.0
#: Most writers whose newest map waits for the graph to name them; beyond, the oldest is refused (maps from many
#: unnamed writers; a flood from one writer keeps only its newest).
MAX_UNDECIDED = 64
#: Most namesakes of the source whose newest sample is kept while the source is ambiguous.
MAX_HELD = 8


def decode_device_map(data: bytes) -> DeviceMap:
    """The DeviceMap of a serialized /tool/device_map message, or ValueError naming what is wrong."""
    try:
        message = deserialize_message(data, TOPICS["device_map"].type)
    except Exception as exc:  # noqa: BLE001 — whatever the deserializer raises on foreign bytes
        raise ValueError(f"the message does not decode as {TOPICS['device_map'].type.__name__}: {exc}") from None
    return device_map_from_message(message)


class DeviceMapSource:
    """The device map samples on `topic` (as `owner` resolves it), judged by their writer (module docstring).

    `on_map(device_map)`: a map from `source_node`; `on_refused(reason, from_source)`: a refused sample, or the source
    ambiguous (from_source True). Counts: `taken`, `refused`; `gate`: the WriterGate."""

    def __init__(self, owner, topic: str, source: str, on_map, on_refused, poll_s: float = MAP_POLL_S,
                 writer_wait_s: float = MAP_WRITER_WAIT_S):
        self._owner = owner
        self.topic = owner.resolve_topic_name(topic)
        self.gate = WriterGate(source_node(owner, source), "device_map_node")
        self._on_map, self._on_refused = on_map, on_refused
        self.writer_wait_s = writer_wait_s
        self._node = rclpy.create_node(f"_{owner.get_name()}_device_map", namespace=owner.get_namespace(),
                                       context=owner.context, use_global_arguments=False,
                                       start_parameter_services=False, enable_rosout=False)
        subscription = self._node.create_subscription(TOPICS["device_map"].type, self.topic, lambda _: None,
                                                      latched_reader_qos(TOPICS["device_map"]), raw=True)
        self._take = SerializedTake(subscription)
        self._undecided: dict[bytes, tuple[Taken, float]] = {}  # GID → (newest sample, monotonic deadline of the first)
        self._held: dict[bytes, bytes] = {}  # GID → newest sample of each writer the graph names as the source
        self.taken = self.refused = 0
        self._timer = owner.create_timer(poll_s, self.poll)

    @property
    def source_node(self) -> str:
        return self.gate.source

    def poll(self) -> None:
        """Take the waiting samples, look at the graph, and judge, in arrival order, every sample whose writer the
        graph names."""
        now = time.monotonic()
        while (sample := self._take()) is not None:  # the map is latched: a writer's newest sample is its map
            first = self._undecided.pop(sample.gid, None)
            self._undecided[sample.gid] = (sample, first[1] if first else now + self.writer_wait_s)
        while len(self._undecided) > MAX_UNDECIDED:
            self._refuse(f"more than {MAX_UNDECIDED} writers' maps wait for their writer to be named", False)
            del self._undecided[next(iter(self._undecided))]
        gate, was_ambiguous = self.gate, self.gate.ambiguous
        update_gates(self._node, {self.topic: gate})
        if gate.ambiguous and not was_ambiguous:
            self._refuse(gate.problem(), True)
        undecided = {}
        for gid, (sample, deadline) in self._undecided.items():
            verdict = gate.judge(gid)
            if gate.from_source(gid):
                self._hold(sample)
            if verdict == UNKNOWN and now < deadline:
                undecided[gid] = (sample, deadline)
            elif verdict == UNKNOWN:
                gate.refuse(sample.gid)
                self._refuse(f"its writer was not named by the ROS graph within {self.writer_wait_s:g} s (it "
                             "published and left before discovery named it)", False)
            elif verdict == ACCEPT:
                self._judge(sample.data)
            elif not gate.from_source(sample.gid):
                self._refuse(f"sent by {gate.writer_name(sample.gid)}; only {self.source_node} may send it "
                             "(parameter device_map_node)", False)
        self._undecided = undecided
        if was_ambiguous and not gate.ambiguous and gate.accepted in self._held:
            self._judge(self._held[gate.accepted])  # resolved: the accepted writer's newest map again

    def _hold(self, sample: Taken) -> None:
        self._held.pop(sample.gid, None)
        self._held[sample.gid] = sample.data
        while len(self._held) > MAX_HELD:
            del self._held[next(iter(self._held))]

    @property
    def waiting(self) -> int:
        """Samples whose writer the graph has not named yet."""
        return len(self._undecided)

    def _judge(self, data: bytes) -> None:
        try:
            device_map = decode_device_map(data)
        except ValueError as exc:
            self._refuse(f"sent by {self.source_node}: {exc}", True)
            return
        self.taken += 1
        self._on_map(device_map)

    def _refuse(self, reason: str, from_source: bool) -> None:
        self.refused += 1
        self._on_refused(reason, from_source)

    def destroy(self) -> None:
        self._owner.destroy_timer(self._timer)
        self._take.close()
        self._node.destroy_node()
